"""One-off exploration behind README "The observer on OpenFace's scale": which linear readouts
of OpenFace's own 3D landmarks reproduce its AU intensities on held-out people.

Reads the real files of experiments/realdata.csv from ../shared/realdata (never copied) and
prints, for several feature sets and fits, the leave-one-person-out Pearson r (mean over the
held-out people, and pooled over their frames) and MAE; then the within-person ceiling (fit on
a clip's first half, read on its second). Needs numpy and scipy (a throwaway venv):

    python3 -m venv /tmp/venv && /tmp/venv/bin/pip install numpy scipy
    /tmp/venv/bin/python tools/observer_exploration/explore.py > results/observer_fit/exploration.txt

The product's readout is Rust (src/observe/features.rs, fit.rs); this script re-implements
its measures only to compare alternatives and is not used by facelab.
"""
import csv, os, sys
import numpy as np
from scipy.optimize import nnls

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
ROOT = os.path.join(REPO, '..', 'shared', 'realdata')
AUS = ["AU01","AU02","AU04","AU05","AU06","AU07","AU09","AU10","AU12","AU14","AU15","AU17","AU20","AU23","AU25","AU26","AU45"]
STABLE = [0, 16, 36, 39, 42, 45]

def load(path):
    with open(path) as f:
        r = csv.reader(f); h = [c.strip() for c in next(r)]
        rows = [[c.strip() for c in row] for row in r if row]
    idx = {n: i for i, n in enumerate(h)}
    A = np.array([[float(x) for x in row] for row in rows])
    A = A[A[:, idx['success']] > 0.5]
    P = np.stack([A[:, [idx[f'{c}_{i}'] for i in range(68)]] for c in 'XYZ'], -1) * np.array([1, -1, -1])
    return P, A[:, [idx[a + '_r'] for a in AUS]]

def kabsch(A, B):
    ca, cb = A.mean(0), B.mean(0)
    U, S, Vt = np.linalg.svd((A - ca).T @ (B - cb)); d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1, 1, d]) @ U.T; return R, cb - R @ ca

def person_frames(P):
    n = np.median(P, 0)
    re, le = n[36:42].mean(0), n[42:48].mean(0); iod = np.linalg.norm(le - re)
    x = (le - re) / iod; up = (le + re) / 2 - n[8]; y = up - x * (up @ x); y /= np.linalg.norm(y)
    ax = np.stack([x, y, np.cross(x, y)]); o = n[STABLE].mean(0)
    out = []
    for p in P:
        R, t = kabsch(n[STABLE], p[STABLE]); out.append((((p - t) @ R) - o) @ ax.T / iod)
    return np.array(out), ((n - o) @ ax.T) / iod

MIR = [16,15,14,13,12,11,10,9,8,7,6,5,4,3,2,1,0,26,25,24,23,22,21,20,19,18,17,27,28,29,30,35,34,33,32,31,45,44,43,42,47,46,39,38,37,36,41,40,54,53,52,51,50,49,48,59,58,57,56,55,64,63,62,61,60,67,66,65]

def disp(P, sym):
    F, nf = person_frames(P); D = F - nf
    if sym: D = 0.5 * (D + D[:, MIR] * np.array([-1, 1, 1]))
    return D.reshape(len(D), -1)

def aperture(p): return np.mean([p[..., u, 1] - p[..., l, 1] for u, l in [(37,41),(38,40),(43,47),(44,46)]], 0)

def measures(P):
    c, n = person_frames(P)
    dy = lambda i: (c[:, i, 1] - n[i, 1]).mean(1)
    out = lambda i: ((c[:, i, 0] - n[i, 0]) * np.sign(n[i, 0])).mean(1)
    back = lambda i: (n[i, 2] - c[:, i, 2]).mean(1)
    dist = lambda a, b: np.linalg.norm(c[:, a] - c[:, b], axis=-1) - np.linalg.norm(n[a] - n[b])
    pos = lambda v: np.maximum(v, 0)
    gap = c[:, 22, 0] - c[:, 21, 0] - (n[22, 0] - n[21, 0])
    cr, co, mid, ec = dy([48, 54]), out([48, 54]), dy([62, 66]), dy([36, 39, 42, 45])
    return np.stack([dy([20,21,22,23]), dy([17,18,25,26]), pos(-dy([19,20,21,22,23,24])) + pos(-gap),
        dy([37,38,43,44]), pos(dy([40,41,46,47])) + 0.5 * pos(-dy([17,18,25,26])), dy([40,41,46,47]) - ec,
        dy([31,35]), dy([50,51,52]), pos(cr) + 0.5 * pos(co),
        np.minimum(back([48,54]), back([48,54]) - 0.5 * (back([49,53]) + back([55,59]))) - 0.5 * np.abs(cr),
        -(cr - mid), dist(57, 8), co - pos(cr), -dist(49, 53), dist(62, 66), dist(30, 8),
        1 - aperture(c) / aperture(n)], 1)

PAIRS = [(19,37),(24,44),(21,39),(22,42),(17,36),(26,45),(21,22),(20,38),(23,43),(37,41),(38,40),(43,47),(44,46),(36,39),(42,45),
 (31,35),(33,51),(31,48),(35,54),(27,33),(48,54),(51,57),(62,66),(50,61),(52,63),(58,65),(56,67),(49,59),(53,55),(60,64),
 (48,36),(54,45),(48,33),(54,33),(48,8),(54,8),(57,8),(30,8),(33,8),(51,33),(48,57),(54,57),(48,51),(54,51),(50,52),(49,53),(55,59),(56,58),(66,57),(62,51)]

def distances(P):
    F, nf = person_frames(P)
    return np.stack([np.linalg.norm(F[:, a] - F[:, b], axis=-1) - np.linalg.norm(nf[a] - nf[b]) for a, b in PAIRS], 1)

pm = lambda M: np.c_[M.clip(0), (-M).clip(0)]

def ridge(lam):
    def fit(Xt, Yt, Xs):
        mu, sd = Xt.mean(0), Xt.std(0) + 1e-9; Z = (Xt - mu) / sd
        W = np.linalg.solve(Z.T @ Z + lam * len(Z) * np.eye(Z.shape[1]), Z.T @ (Yt - Yt.mean(0)))
        return ((Xs - mu) / sd) @ W + Yt.mean(0)
    return fit

def nonneg(Xt, Yt, Xs):
    mu = Xt.mean(0); Xc = Xt - mu; G = Xc.T @ Xc / len(Xc); G += 1e-3 * np.trace(G) / len(G) * np.eye(len(G))
    L = np.linalg.cholesky(G); out = np.zeros((len(Xs), 17))
    for k in range(17):
        w, _ = nnls(L.T, np.linalg.solve(L, Xc.T @ (Yt[:, k] - Yt[:, k].mean()) / len(Xc)))
        out[:, k] = (Xs - mu) @ w + Yt[:, k].mean()
    return out

def rows_of(path):
    people = {}
    with open(path) as f:
        for r in csv.DictReader(l for l in f if not l.startswith('#')):
            people.setdefault(r['person'], []).append(os.path.join(ROOT, r['file']))
    return people

def main():
    if not os.path.isdir(ROOT):
        sys.exit(f'{ROOT}: the real OpenFace files are not here')
    people = rows_of(os.path.join(REPO, 'experiments', 'realdata.csv'))
    clips = {p: [load(f) for f in fs] for p, fs in people.items()}
    trials = [
        ('ridge, 204 aligned displacements', lambda P: disp(P, False), ridge(0.1)),
        ('ridge, displacements made symmetric', lambda P: disp(P, True), ridge(0.1)),
        ('ridge, hand measures +/-', lambda P: pm(measures(P)), ridge(0.01)),
        ('nonnegative, hand measures +/-', lambda P: pm(measures(P)), nonneg),
        ('nonnegative, distances +/-', lambda P: pm(distances(P)), nonneg),
        ('nonnegative, measures + distances +/- (the readout, before its stretch)', lambda P: np.c_[pm(measures(P)), pm(distances(P))], nonneg),
    ]
    names = sorted(clips)
    for label, feat, fit in trials:
        X = {p: np.vstack([feat(P) for P, _ in clips[p]]) for p in names}
        Y = {p: np.vstack([a for _, a in clips[p]]) for p in names}
        R, preds, ys = [], [], []
        for p in names:
            tr = [q for q in names if q != p]
            pr = np.clip(fit(np.vstack([X[q] for q in tr]), np.vstack([Y[q] for q in tr]), X[p]), 0, 5)
            with np.errstate(all='ignore'):
                R.append([np.corrcoef(pr[:, k], Y[p][:, k])[0, 1] for k in range(17)])
            preds.append(pr); ys.append(Y[p])
        P_, Y_ = np.vstack(preds), np.vstack(ys)
        pooled = [np.corrcoef(P_[:, k], Y_[:, k])[0, 1] for k in range(17)]
        print(f'{label}: held-out mean r per person {np.nanmean(R):.3f}, pooled {np.nanmean(pooled):.3f}, MAE {np.abs(P_ - Y_).mean():.3f}')
    print('within one person (fit on the first half of each clip, read the second), ridge on displacements:')
    for p in names:
        for P, au in clips[p]:
            D = disp(P, False); h = len(D) // 2
            pr = ridge(0.1)(D[:h], au[:h], D[h:])
            with np.errstate(all='ignore'):
                r = [np.corrcoef(pr[:, k], au[h:, k])[0, 1] for k in range(17)]
            print(f'  {p} ({len(D)} frames): mean r {np.nanmean(r):.2f}')

main()

def smile_scale():
    P, au = load(os.path.join(ROOT, 'exploface-Apache-2.0', 'video2.csv'))
    m = measures(P)[:, 8]
    hi = au[:, 8] >= 2
    print(f'exploface frames with OpenFace AU12 >= 2: {hi.sum()}, their mean AU12 {au[hi, 8].mean():.2f}, '
          f'median AU12 measure {np.median(m[hi]):.3f} IOD')

smile_scale()
