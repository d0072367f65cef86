//! Summary statistics for tables (DESIGN 3: means over seeds with a 95% interval). Pure; uses
//! nothing else from the crate.

/// Two-sided 97.5% quantiles of Student's t for 1..=30 degrees of freedom (standard table).
const T975: [f64; 30] = [
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
    2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
    2.052, 2.048, 2.045, 2.042,
];

/// The mean (NaN for no values).
pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// The median (NaN for no values; the mean of the middle two for an even count); sorts
/// `values`.
pub fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// The mean, 0 for no values (a mean error over nothing).
pub fn mean_or_zero(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// The mean of the squares, 0 for no values: the MSE of differences.
pub fn mean_square(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64
}

/// The root mean square, 0 for no values.
pub fn rms(v: &[f64]) -> f64 {
    mean_square(v).sqrt()
}

/// The mean squared difference of two equally long samples, 0 for none.
pub fn mse(a: &[f64], b: &[f64]) -> f64 {
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    mean_square(&d)
}

/// The smallest and largest value (infinities for no values).
pub fn min_max(v: &[f64]) -> (f64, f64) {
    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (lo, hi)
}

/// Mean and population standard deviation (divided by n; 0 and 0 for no values).
pub fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len().max(1) as f64;
    let mean = v.iter().sum::<f64>() / n;
    let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    (mean, sd)
}

/// Half-width of the 95% confidence interval of the mean (t distribution); 0 for one value.
pub fn ci95(v: &[f64]) -> f64 {
    let n = v.len();
    if n < 2 {
        return 0.0;
    }
    let m = mean(v);
    let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    let t = T975.get(n - 2).copied().unwrap_or(1.96);
    t * sd / (n as f64).sqrt()
}

/// Pearson's correlation of two equally long samples (NaN where either is constant).
pub fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa == 0.0 || sbb == 0.0 {
        f64::NAN
    } else {
        sab / (saa * sbb).sqrt()
    }
}

/// The mean absolute difference of two equally long samples.
pub fn mean_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interval_of_known_sample() {
        // mean 3, sd sqrt(2.5), n 5: 2.776 * 1.5811 / 2.2361 = 1.9629.
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(mean(&v), 3.0);
        assert!((ci95(&v) - 1.9629).abs() < 1e-3);
        assert_eq!(ci95(&[2.0]), 0.0);
    }

    #[test]
    fn errors_of_known_samples() {
        assert_eq!(mean_square(&[3.0, 4.0]), 12.5);
        assert_eq!(rms(&[3.0, 4.0]), 12.5f64.sqrt());
        assert_eq!(mse(&[1.0, 2.0], &[1.0, 4.0]), 2.0);
        assert_eq!((rms(&[]), mean_or_zero(&[])), (0.0, 0.0));
        assert!(mean(&[]).is_nan());
        assert_eq!(min_max(&[2.0, -1.0, 5.0]), (-1.0, 5.0));
        assert_eq!(mean_sd(&[1.0, 3.0]), (2.0, 1.0));
    }
}
