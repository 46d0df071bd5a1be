"""Error metrics."""
import numpy as np


def relmse(image, reference, eps=0.01):
    """Relative MSE: mean over pixels and channels of (x - ref)^2 / (ref^2 + eps)."""
    x = np.asarray(image, np.float64)
    r = np.asarray(reference, np.float64)
    return float(np.mean((x - r) ** 2 / (r * r + eps)))
