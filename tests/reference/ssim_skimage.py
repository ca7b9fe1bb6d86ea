"""Reference values for eval::ssim_masked and eval::psnr_masked: scikit-image's SSIM
(7x7 uniform window, sample covariance, data_range 255, channel_axis=-1, full map) averaged
over a mask, and PSNR over the masked pixels. Writes tests/data/ssim_skimage.json."""
import json
import pathlib

import numpy as np
from skimage.metrics import structural_similarity

rng = np.random.default_rng(3)
h, w = 30, 41
y, x = np.mgrid[0:h, 0:w]
base = np.stack([120 + 80 * np.sin(x / 5.0), 100 + 60 * np.cos(y / 4.0), (x * 3 + y * 2) % 256], -1)
a = np.clip(base, 0, 255).astype(np.uint8)
b = np.clip(base + rng.normal(0, 12, base.shape) + 10 * (x > 20)[..., None], 0, 255).astype(np.uint8)
mask = ((x - 20) ** 2 / 15**2 + (y - 15) ** 2 / 11**2) <= 1.0

_, smap = structural_similarity(a, b, channel_axis=-1, data_range=255, full=True)
ssim = float(np.mean([smap[..., c][mask].mean() for c in range(3)]))
d = a.astype(float)[mask] - b.astype(float)[mask]
psnr = float(10 * np.log10(255.0**2 / np.mean(d**2)))

out = pathlib.Path(__file__).resolve().parents[1] / "data" / "ssim_skimage.json"
out.write_text(json.dumps({
    "width": w, "height": h,
    "a": a.ravel().tolist(), "b": b.ravel().tolist(),
    "mask": mask.ravel().astype(int).tolist(),
    "ssim": ssim, "psnr": psnr,
    "ssim_unmasked": float(structural_similarity(a, b, channel_axis=-1, data_range=255)),
}))
print(out, ssim, psnr)
