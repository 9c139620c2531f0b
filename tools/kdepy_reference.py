#!/usr/bin/env python3
"""Dev-time oracle: the original (KDEpy-based) refinement rules and voxpan's mask protocol.

Not part of the product. Used to (1) generate golden numbers for voxpan's KDEpy-compatible
mode, (2) check that `voxpan refine --rule paper|release` agrees with the original per pixel,
(3) check the mask-protocol golden numbers of the brief.

    pip install KDEpy==1.1.12 scipy numpy tifffile pillow
    python3 tools/kdepy_reference.py eval   ../shared/data/flat            # protocol numbers
    python3 tools/kdepy_reference.py refine ../shared/data/flat OUTDIR     # reference masks
    python3 tools/kdepy_reference.py agree  ../shared/data/flat RUSTDIR    # per-pixel agreement
    python3 tools/kdepy_reference.py golden OUT.json                       # KDE golden numbers

The rules follow the released code: `remove_depth_outliers.py` (paper: raw depth, cut-off 1e-6)
and `utils.remove_outliers` (release: depth normalised to [0,1], cut-off max(y[:peak])/20), with
KDEpy's ISJ patched as the released code ships it (t* = 0.01 when the root search fails).
"""
import json
import os
import sys
import time

import numpy as np
import tifffile
from PIL import Image
from scipy.optimize import brentq, linear_sum_assignment
from scipy.signal import find_peaks

import KDEpy.bw_selection as bws
from KDEpy import FFTKDE


def _root_released(function, N, args):
    # The released code's KDEpy_mod: like KDEpy 1.1.x, but t* = 0.01 instead of an exception.
    N = max(min(1050, N), 50)
    tol = 10e-12 + 0.01 * (N - 50) / 1000
    found = 0
    while found == 0:
        try:
            x, res = brentq(function, 0, tol, args=args, full_output=True, disp=False)
            found = 1 if res.converged else 0
        except ValueError:
            x = 0
            tol *= 2.0
            found = 0
        if x <= 0:
            found = 0
        if tol >= 1:
            return 0.01
    return x


bws._root = _root_released


def kde(zs):
    return FFTKDE(kernel="gaussian", bw="ISJ", norm=1).fit(zs).evaluate()


def bounds_paper(zs):
    xz, yz = kde(zs)
    peaks, _ = find_peaks(yz, max(yz))
    p = peaks[0]
    left = np.where(yz[:p] < 1e-6)[0][-1]
    right = np.where(yz[p:] < 1e-6)[0][0] + p
    return xz[left], xz[right]


def bounds_release(zs):
    zmin, zmax = zs.min(), zs.max()
    zn = (zs - zmin) / (zmax - zmin)
    xz, yz = kde(zn)
    xz = xz * (zmax - zmin) + zmin
    peaks, _ = find_peaks(yz, max(yz))
    p = peaks[0]
    cut = max(yz[:p] / 20)
    left = np.where(yz[:p] < cut)[0][-1]
    right = np.where(yz[p:] < cut)[0][0] + p
    return xz[left], xz[right]


RULES = {"paper": bounds_paper, "release": bounds_release}


def refine_frame(depth, pred, rule):
    out = pred.copy()
    for sid in np.unique(pred):
        if sid == 0:
            continue
        mask = pred == sid
        zs = depth[mask]
        zs = zs[zs > 0]
        try:
            low, high = RULES[rule](zs)
        except Exception:  # the original crashes here; keep the mask as voxpan does
            continue
        d = depth.copy()
        d[(d < low) | (d > high)] = 0
        out[mask & (d == 0)] = 0
    return out


def frames(flat):
    run = os.path.join(flat, "run1")
    ids = sorted(f[:6] for f in os.listdir(run) if f.endswith("_predicted.png"))
    for fid in ids:
        depth = tifffile.imread(os.path.join(run, fid + "_depth.tiff"))
        pred = np.array(Image.open(os.path.join(run, fid + "_predicted.png")))
        gt = np.array(Image.open(os.path.join(run, fid + "_segmentation.png")))
        if gt.ndim == 3:
            gt = gt[..., 0]
        yield fid, depth, pred, gt


def match_frame(pred, gt):
    """Per-frame Hungarian matching on IoU; predicted = non-zero ids, ground truth = all ids."""
    pids = [i for i in np.unique(pred) if i != 0]
    gids = list(np.unique(gt))
    iou = np.zeros((len(pids), len(gids)))
    for a, p in enumerate(pids):
        pm = pred == p
        for b, g in enumerate(gids):
            gm = gt == g
            inter = np.logical_and(pm, gm).sum()
            if inter:
                iou[a, b] = inter / np.logical_or(pm, gm).sum()
    r, c = linear_sum_assignment(-iou)
    return [iou[i, j] for i, j in zip(r, c)], len(pids), len(gids)


def score(pairs):
    ious, n_pred, n_gt = [], 0, 0
    for matched, np_, ng in pairs:
        ious += matched
        n_pred += np_
        n_gt += ng
    pos = [x for x in ious if x > 0]
    tp = [x for x in ious if x > 0.5]
    sq = np.mean(tp) if tp else 0.0
    rq = len(tp) / (len(tp) + (n_pred - len(tp)) / 2 + (n_gt - len(tp)) / 2)
    return dict(mean_matched_iou=100 * np.mean(pos), pq=100 * sq * rq, sq=100 * sq, rq=100 * rq,
                tp=len(tp), n_pred=n_pred, n_gt=n_gt)


def cmd_eval(flat):
    res = {r: [] for r in ["none", "paper", "release"]}
    times = []
    for fid, depth, pred, gt in frames(flat):
        res["none"].append(match_frame(pred, gt))
        for rule in ["paper", "release"]:
            t0 = time.perf_counter()
            refined = refine_frame(depth, pred, rule)
            times.append(time.perf_counter() - t0)
            res[rule].append(match_frame(refined, gt))
    for rule, pairs in res.items():
        print(rule, json.dumps(score(pairs)))
    print("original refinement ms/frame (median):", 1000 * np.median(times))


def cmd_refine(flat, outdir):
    os.makedirs(outdir, exist_ok=True)
    for fid, depth, pred, gt in frames(flat):
        for rule in ["paper", "release"]:
            Image.fromarray(refine_frame(depth, pred, rule)).save(os.path.join(outdir, f"{fid}_{rule}.png"))


def cmd_agree(flat, rustdir):
    worst = {}
    for fid, depth, pred, gt in frames(flat):
        for rule in ["paper", "release"]:
            ref = refine_frame(depth, pred, rule)
            ours = np.array(Image.open(os.path.join(rustdir, f"{fid}_{rule}.png")))
            agree = (ref == ours).mean()
            worst[rule] = min(worst.get(rule, 1.0), agree)
            if agree < 0.995:
                print(f"frame {fid} rule {rule}: agreement {100 * agree:.3f}%")
    print("worst per-frame agreement:", {k: f"{100 * v:.4f}%" for k, v in worst.items()})


def botev_isj_bandwidth(data):
    """Botev's algorithm (grid padded by range/10, bandwidth = sqrt(t*) x grid range), built
    from KDEpy's own binning, DCT and fixed-point function, with Botev's root bracketing."""
    lo, hi = data.min(), data.max()
    pad = (hi - lo) / 10
    grid = np.linspace(lo - pad, hi + pad, 1024)
    w = bws.linear_binning(data.reshape(-1, 1), grid.reshape(-1, 1), None)
    a = bws.fftpack.dct(w)
    I_sq = np.power(np.arange(1, 1024, dtype=np.float64), 2)
    N = len(np.unique(data))
    n = max(min(1050, N), 50)
    tol = 1e-12 + 0.01 * (n - 50) / 1000
    while True:
        try:
            t = brentq(bws._fixed_point, 0, tol, args=(N, I_sq, a[1:] ** 2))
            if t > 0:
                break
        except ValueError:
            pass
        tol = min(2 * tol, 0.1)
        if tol >= 0.1:
            raise RuntimeError("no root")
    return np.sqrt(t) * (grid[-1] - grid[0])


def cmd_golden(out):
    """Bandwidths and density samples of KDEpy on fixed inputs (written as JSON)."""
    rng = np.random.default_rng(7)
    b = np.concatenate([rng.normal(1.5, 0.05, 1400), rng.normal(3.0, 0.2, 600)])
    cases = {
        "normal_1000": rng.normal(2.0, 0.3, 1000),
        "bimodal_2000": b,
        "uniform_200": rng.uniform(0.5, 4.0, 200),
        "small_normal_30": rng.normal(0.0, 1.0, 30),
        "normalised_bimodal": (b - b.min()) / (b.max() - b.min()),
        "depth_mm_bimodal": 1000 * b,
    }
    res = {}
    for name, data in cases.items():
        bw = bws.improved_sheather_jones(data.reshape(-1, 1))
        x, y = kde(data)
        res[name] = dict(data=[float(v) for v in data], kdepy_bandwidth=float(bw),
                         botev_bandwidth=float(botev_isj_bandwidth(data)),
                         x0=float(x[0]), x_last=float(x[-1]),
                         y_samples={str(i): float(y[i]) for i in range(0, 1024, 31)},
                         argmax=int(np.argmax(y)))
    with open(out, "w") as f:
        json.dump(res, f)


if __name__ == "__main__":
    cmd = sys.argv[1]
    {"eval": cmd_eval, "refine": cmd_refine, "agree": cmd_agree, "golden": cmd_golden}[cmd](*sys.argv[2:])
