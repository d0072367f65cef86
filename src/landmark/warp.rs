//! Frames, MediaPipe's rotated regions of interest, and the affine crop that feeds a network.

/// An RGB image, 8 bits per channel, rows top to bottom, interleaved.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbFrame {
    pub width: usize,
    pub height: usize,
    pub data: Vec<u8>,
}

impl RgbFrame {
    pub fn new(width: usize, height: usize, data: Vec<u8>) -> RgbFrame {
        assert_eq!(data.len(), width * height * 3, "RGB frame size");
        RgbFrame {
            width,
            height,
            data,
        }
    }

    fn pixel(&self, x: usize, y: usize) -> [f32; 3] {
        let i = 3 * (y * self.width + x);
        [
            self.data[i] as f32,
            self.data[i + 1] as f32,
            self.data[i + 2] as f32,
        ]
    }
}

/// A rotated rectangle in image pixels (MediaPipe's `RotatedRect`): centre, size, and the
/// rotation (radians, clockwise on screen since y points down) that turns the crop's axes
/// onto the image's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RotatedRect {
    pub center: [f64; 2],
    pub width: f64,
    pub height: f64,
    pub rotation: f64,
}

/// Pixels outside the image: black (the detector's letterbox) or the nearest edge pixel (the
/// landmark crop, MediaPipe's default).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Border {
    Zero,
    Replicate,
}

impl RotatedRect {
    /// The whole image padded to a square about its centre (the detector's letterbox).
    pub fn letterbox(width: usize, height: usize) -> RotatedRect {
        let side = width.max(height) as f64;
        RotatedRect {
            center: [width as f64 / 2.0, height as f64 / 2.0],
            width: side,
            height: side,
            rotation: 0.0,
        }
    }

    /// MediaPipe's face crop: a box about `center` of size `width` x `height`, turned so that
    /// the line from `start` to `end` (the eyes) becomes horizontal, made square on its long
    /// side and scaled 1.5x (`face_detection_front_detection_to_roi`).
    pub fn face(
        center: [f64; 2],
        width: f64,
        height: f64,
        start: [f64; 2],
        end: [f64; 2],
    ) -> RotatedRect {
        let rotation = normalize_radians(-(-(end[1] - start[1])).atan2(end[0] - start[0]));
        let side = width.max(height) * 1.5;
        RotatedRect {
            center,
            width: side,
            height: side,
            rotation,
        }
    }

    /// The Face Landmarker task's crop of a detection (`FaceDetectorGraph`'s expanded rect): the
    /// box turned so that the eyes are level and scaled 1.5x on each side, not made square;
    /// the landmark network's input stretches it onto its square.
    pub fn face_box(
        center: [f64; 2],
        width: f64,
        height: f64,
        start: [f64; 2],
        end: [f64; 2],
    ) -> RotatedRect {
        let square = RotatedRect::face(center, width, height, start, end);
        RotatedRect {
            width: width * 1.5,
            height: height * 1.5,
            ..square
        }
    }

    /// The crop for the next video frame from this frame's landmarks
    /// (`face_landmark_landmarks_to_roi`): their bounding box, turned by the eye corners 33
    /// and 263.
    pub fn from_landmarks(points: &[[f64; 3]]) -> RotatedRect {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in points {
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let center = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        let eye = |i: usize| [points[i][0], points[i][1]];
        RotatedRect::face(center, hi[0] - lo[0], hi[1] - lo[1], eye(33), eye(263))
    }

    /// Image pixel of the crop-normalized point `(u, v)` in [0, 1]^2, with a depth `z` in
    /// crop widths scaled to pixels like x (`LandmarkProjectionCalculator`).
    pub fn to_image(&self, [u, v]: [f64; 2], z: f64) -> [f64; 3] {
        let (x, y) = (u - 0.5, v - 0.5);
        let (s, c) = self.rotation.sin_cos();
        [
            self.center[0] + (c * x - s * y) * self.width,
            self.center[1] + (s * x + c * y) * self.height,
            z * self.width,
        ]
    }
}

/// Angle in [-pi, pi).
fn normalize_radians(a: f64) -> f64 {
    use std::f64::consts::PI;
    a - 2.0 * PI * ((a + PI) / (2.0 * PI)).floor()
}

/// The `size` x `size` crop of `rect`, bilinearly sampled, as interleaved RGB scaled from
/// [0, 255] onto `range` (OpenCV's warp as MediaPipe's `ImageToTensorCalculator` uses it:
/// output pixel `(i, j)` reads the image at the rect point `(j / size, i / size)`).
pub fn crop(
    frame: &RgbFrame,
    rect: &RotatedRect,
    size: usize,
    border: Border,
    range: [f32; 2],
) -> Vec<f32> {
    let scale = (range[1] - range[0]) / 255.0;
    let mut out = Vec::with_capacity(size * size * 3);
    let n = size as f64;
    for i in 0..size {
        for j in 0..size {
            let [x, y, _] = rect.to_image([j as f64 / n, i as f64 / n], 0.0);
            let rgb = sample(frame, x, y, border);
            out.extend(rgb.iter().map(|v| v * scale + range[0]));
        }
    }
    out
}

/// Bilinear sample at pixel coordinates (pixel centres at integers).
fn sample(frame: &RgbFrame, x: f64, y: f64, border: Border) -> [f32; 3] {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    let (w, h) = (frame.width as i64, frame.height as i64);
    let at = |xi: i64, yi: i64| -> [f32; 3] {
        let inside = (0..w).contains(&xi) && (0..h).contains(&yi);
        match (inside, border) {
            (true, _) => frame.pixel(xi as usize, yi as usize),
            (false, Border::Zero) => [0.0; 3],
            (false, Border::Replicate) => {
                frame.pixel(xi.clamp(0, w - 1) as usize, yi.clamp(0, h - 1) as usize)
            }
        }
    };
    let (xi, yi) = (x0 as i64, y0 as i64);
    let (a, b, c, d) = (
        at(xi, yi),
        at(xi + 1, yi),
        at(xi, yi + 1),
        at(xi + 1, yi + 1),
    );
    let mut out = [0.0; 3];
    for k in 0..3 {
        let top = a[k] + (b[k] - a[k]) * fx;
        let bottom = c[k] + (d[k] - c[k]) * fx;
        out[k] = top + (bottom - top) * fy;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crop_of_the_whole_image_reproduces_it() {
        let data: Vec<u8> = (0..4 * 4 * 3).map(|i| (i * 5) as u8).collect();
        let frame = RgbFrame::new(4, 4, data.clone());
        let out = crop(
            &frame,
            &RotatedRect::letterbox(4, 4),
            4,
            Border::Zero,
            [0.0, 255.0],
        );
        let got: Vec<u8> = out.iter().map(|v| v.round() as u8).collect();
        assert_eq!(got, data);
    }

    #[test]
    fn projection_inverts_the_rotation() {
        let rect = RotatedRect {
            center: [100.0, 50.0],
            width: 40.0,
            height: 40.0,
            rotation: 0.3,
        };
        // The crop's right edge midpoint lies along the rotated x axis.
        let p = rect.to_image([1.0, 0.5], 0.0);
        assert!((p[0] - (100.0 + 20.0 * 0.3f64.cos())).abs() < 1e-12);
        assert!((p[1] - (50.0 + 20.0 * 0.3f64.sin())).abs() < 1e-12);
        // Eyes level: no rotation; eyes tilted (right eye lower on screen): positive rotation.
        let level = RotatedRect::face([0.0, 0.0], 10.0, 10.0, [0.0, 0.0], [10.0, 0.0]);
        assert_eq!(level.rotation, 0.0);
        let tilted = RotatedRect::face([0.0, 0.0], 10.0, 10.0, [0.0, 0.0], [10.0, 10.0]);
        assert!((tilted.rotation - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        assert_eq!(tilted.width, 15.0);
    }
}
