"""Image helpers shared by policy adapters."""

from __future__ import annotations

import cv2
import numpy as np


def resize_with_pad(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """Letterbox ``image`` (H, W, C) uint8 to (height, width): keep the aspect ratio, pad with black, centred."""
    image = np.asarray(image)
    if image.ndim != 3:
        raise ValueError(f"expected an (H, W, C) image, got shape {image.shape}")
    h, w = image.shape[:2]
    if (h, w) == (height, width):
        return np.ascontiguousarray(image, dtype=np.uint8)
    scale = min(height / h, width / w)
    new_h, new_w = max(1, round(h * scale)), max(1, round(w * scale))
    interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
    resized = cv2.resize(np.ascontiguousarray(image, dtype=np.uint8), (new_w, new_h), interpolation=interp)
    if resized.ndim == 2:
        resized = resized[:, :, None]
    out = np.zeros((height, width, image.shape[2]), dtype=np.uint8)
    top, left = (height - new_h) // 2, (width - new_w) // 2
    out[top : top + new_h, left : left + new_w] = resized
    return out


def resize_with_pad_pil(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """Letterbox as openpi's client (``image_tools.resize_with_pad``) and MolmoSpaces' pi policy do:
    PIL bilinear to the aspect-kept size (truncated to whole pixels), pasted centred on black."""
    from PIL import Image

    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) RGB image, got shape {image.shape}")
    h, w = image.shape[:2]
    if (h, w) == (height, width):
        return image
    ratio = max(w / width, h / height)
    new_h, new_w = int(h / ratio), int(w / ratio)
    src = Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8))
    out = np.zeros((height, width, 3), dtype=np.uint8)
    top, left = max(0, int((height - new_h) / 2)), max(0, int((width - new_w) / 2))
    resized = src.resize((new_w, new_h), resample=Image.Resampling.BILINEAR)
    out[top : top + new_h, left : left + new_w] = np.asarray(resized)
    return out
