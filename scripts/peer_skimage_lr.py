#!/usr/bin/env python3
"""Reference data for `tests/peer_skimage_lr.rs`: scikit-image's Lucy–Richardson on small checked-in arrays.

Two cases, each written as `tests/data/peers/skimage/<case>_{observed,kernel,skimage}.npy` (float64, C order,
rows = y, columns = x):

* `smooth`: 64 x 64, blobs on a floor of 0.2 blurred by a 9 x 9 Gaussian (sigma 1.5 cells), 50 iterations;
* `compact`: 48 x 40 (nx = 48 columns, ny = 40 rows), an observation that is exactly zero beyond a margin,
  blurred by an asymmetric 7 x 5 kernel (kw = 7 columns, kh = 5 rows; not symmetric, so the mirrored kernel
  of the correction step matters), 30 iterations.

`skimage.restoration.richardson_lucy(observed, kernel, num_iter, clip=False)` with `filter_epsilon=None`.
Per iteration it computes `conv = convolve(est, K, 'same') + 1e-12`, `est *= convolve(observed / conv,
flip(K), 'same')`, from `est = 0.5` everywhere; scipy's `convolve` in mode 'same' is the linear convolution
with zeros outside the grid, cropped to the centre (odd kernels: centred on the kernel's middle). That is
the operation brdfmill's `LucyRichardson` does with its zero-padded FFTs, so the test starts brdfmill from
0.5 too and compares every cell (see the test for the one difference, the 1e-12). The kernels are written
with unit sum, as brdfmill normalises them and scikit-image does not.

Written with Python 3.11.7, NumPy 2.4.6, SciPy 1.17.1, scikit-image 0.26.0:

    python3 -m venv /work/venv && /work/venv/bin/pip install numpy==2.4.6 scipy==1.17.1 scikit-image==0.26.0
    /work/venv/bin/python scripts/peer_skimage_lr.py tests/data/peers/skimage
"""
import sys
from pathlib import Path

import numpy as np
import scipy
import skimage
from scipy.signal import convolve
from skimage.restoration import richardson_lucy


def gaussian_kernel(kw, kh, sx, sy, cx=0.0, cy=0.0, skew=0.0):
    x = np.arange(kw) - kw // 2
    y = np.arange(kh) - kh // 2
    xx, yy = np.meshgrid(x, y)  # rows = y, columns = x
    k = np.exp(-0.5 * (((xx - cx) / sx) ** 2 + ((yy - cy) / sy) ** 2)) * (1.0 + skew * xx * (xx > 0))
    return k / k.sum()


def smooth_case():
    ny = nx = 64
    y, x = np.mgrid[0:ny, 0:nx].astype(float)
    truth = 0.2 + np.zeros((ny, nx))
    for (cx, cy, s, a) in [(20, 18, 3.0, 1.0), (41, 30, 5.0, 0.6), (30, 47, 2.0, 0.8), (52, 52, 4.0, 0.4)]:
        truth += a * np.exp(-0.5 * ((x - cx) ** 2 + (y - cy) ** 2) / s**2)
    kernel = gaussian_kernel(9, 9, 1.5, 1.5)
    observed = convolve(truth, kernel, mode="same")
    return observed, kernel, 50


def compact_case():
    ny, nx = 40, 48
    y, x = np.mgrid[0:ny, 0:nx].astype(float)
    truth = np.exp(-0.5 * (((x - 21.0) / 6.0) ** 2 + ((y - 17.0) / 4.0) ** 2)) + 0.5 * np.exp(
        -0.5 * (((x - 30.0) / 3.0) ** 2 + ((y - 24.0) / 5.0) ** 2)
    )
    truth[(x < 8) | (x > 41) | (y < 6) | (y > 33)] = 0.0
    kernel = gaussian_kernel(7, 5, 1.4, 0.9, cx=0.6, cy=-0.3, skew=0.3)
    observed = convolve(truth, kernel, mode="same")
    observed[np.abs(observed) < 1e-300] = 0.0
    observed = np.maximum(observed, 0.0)
    return observed, kernel, 30


def main():
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    for name, (observed, kernel, iterations) in [("smooth", smooth_case()), ("compact", compact_case())]:
        observed = np.ascontiguousarray(observed, dtype=np.float64)
        kernel = np.ascontiguousarray(kernel, dtype=np.float64)
        result = richardson_lucy(observed, kernel, num_iter=iterations, clip=False)
        assert result.dtype == np.float64
        np.save(out / f"{name}_observed.npy", observed)
        np.save(out / f"{name}_kernel.npy", kernel)
        np.save(out / f"{name}_skimage.npy", np.ascontiguousarray(result))
        print(
            f"{name}: observed {observed.shape}, kernel {kernel.shape}, {iterations} iterations, "
            f"result range [{result.min():.6g}, {result.max():.6g}]"
        )
    print(f"numpy {np.__version__}, scipy {scipy.__version__}, scikit-image {skimage.__version__}")


if __name__ == "__main__":
    main()
