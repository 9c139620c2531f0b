"""Pre/post-processing shared by the check and golden scripts.

Written to be easy to mirror in Rust: the letterbox is integer-exact (pads are
floor/ceil of half the slack) and the resize is plain bilinear with half-pixel
centres and no antialiasing (what OpenCV's INTER_LINEAR does).
"""

import ast
import json

import numpy as np

PAD_VALUE = 114


def read_rgb(path):
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))


def resize_bilinear(img, nh, nw):
    """HxWxC array -> nh x nw x C float32, half-pixel centres, edge clamp."""
    h, w = img.shape[:2]
    if (h, w) == (nh, nw):
        return img.astype(np.float32)

    def axis(n_out, n_in):
        src = (np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5
        src = np.clip(src, 0, n_in - 1)
        i0 = np.floor(src).astype(np.int64)
        i1 = np.minimum(i0 + 1, n_in - 1)
        return i0, i1, (src - i0).astype(np.float32)

    y0, y1, fy = axis(nh, h)
    x0, x1, fx = axis(nw, w)
    f = img.astype(np.float32)
    top = f[y0][:, x0] * (1 - fx)[None, :, None] + f[y0][:, x1] * fx[None, :, None]
    bot = f[y1][:, x0] * (1 - fx)[None, :, None] + f[y1][:, x1] * fx[None, :, None]
    return top * (1 - fy)[:, None, None] + bot * fy[:, None, None]


def letterbox(img, H, W):
    """Scale to fit H x W keeping aspect, pad with gray 114 centred.

    Returns (tensor [1,3,H,W] float32 RGB in [0,1], r, (left, top)): an input
    pixel maps to ((x - left) / r, (y - top) / r) in the original image.
    """
    h, w = img.shape[:2]
    r = min(H / h, W / w)
    nh, nw = int(round(h * r)), int(round(w * r))
    top, left = (H - nh) // 2, (W - nw) // 2
    canvas = np.full((H, W, 3), PAD_VALUE, np.float32)
    # Round the resized pixels to uint8 first, as an 8-bit image resize would.
    canvas[top:top + nh, left:left + nw] = np.clip(np.round(resize_bilinear(img, nh, nw)), 0, 255)
    x = (canvas / 255.0).transpose(2, 0, 1)[None].astype(np.float32)
    return np.ascontiguousarray(x), r, (left, top)


def parse_names(s):
    """`names` metadata: python dict repr (what YOLO exports write) or JSON."""
    try:
        d = json.loads(s)
    except json.JSONDecodeError:
        d = ast.literal_eval(s)
    if isinstance(d, list):
        d = dict(enumerate(d))
    return {int(k): v for k, v in d.items()}


def decode(out0, meta, conf_thres=0.25):
    """Raw output0 -> (boxes xyxy [K,4], scores [K], classes [K], coefs [K,nm])
    in input pixels, before NMS. Layout from metadata (`layout` key) or shape."""
    nc = len(parse_names(meta["names"]))
    if meta.get("layout") == "yolov5-seg":
        p = out0[0]  # [N, 5+nc+nm]
        obj, cls, coef = p[:, 4], p[:, 5:5 + nc], p[:, 5 + nc:]
        best = cls.argmax(1)
        score = obj * cls[np.arange(len(p)), best]
        keep = (obj > conf_thres) & (score > conf_thres)
    else:  # ultralytics v8/11: [4+nc+nm, N], no objectness
        p = out0[0].T
        cls, coef = p[:, 4:4 + nc], p[:, 4 + nc:]
        best = cls.argmax(1)
        score = cls[np.arange(len(p)), best]
        keep = score > conf_thres
    cx, cy, w, h = p[:, 0], p[:, 1], p[:, 2], p[:, 3]
    boxes = np.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], 1)
    return boxes[keep], score[keep], best[keep], coef[keep]


def iou_one(b, bs):
    lt = np.maximum(b[:2], bs[:, :2])
    rb = np.minimum(b[2:], bs[:, 2:])
    inter = np.prod(np.clip(rb - lt, 0, None), 1)
    area = lambda x: (x[..., 2] - x[..., 0]) * (x[..., 3] - x[..., 1])
    return inter / (area(b) + area(bs) - inter + 1e-9)


def nms(boxes, scores, classes, iou_thres=0.45):
    """Greedy class-aware NMS; returns kept indices by descending score."""
    order = np.argsort(-scores, kind="stable")
    keep = []
    while order.size:
        i = order[0]
        keep.append(i)
        rest = order[1:]
        same = classes[rest] == classes[i]
        drop = same & (iou_one(boxes[i], boxes[rest]) > iou_thres)
        order = rest[~drop]
    return np.array(keep, np.int64)


def masks(coefs, protos, boxes, H, W):
    """Instance masks at input resolution: sigmoid(coef . protos) upsampled x4
    (bilinear) from prototype resolution, thresholded at 0.5, cropped to the box."""
    nm, ph, pw = protos.shape
    m = 1 / (1 + np.exp(-(coefs @ protos.reshape(nm, -1)))).reshape(-1, ph, pw)
    out = np.zeros((len(m), H, W), bool)
    ys, xs = np.arange(H)[:, None] + 0.5, np.arange(W)[None, :] + 0.5
    for k, b in enumerate(boxes):
        up = resize_bilinear(m[k][..., None], H, W)[..., 0]
        inside = (xs >= b[0]) & (xs < b[2]) & (ys >= b[1]) & (ys < b[3])
        out[k] = (up > 0.5) & inside
    return out


def read_metadata(session):
    return dict(session.get_modelmeta().custom_metadata_map)
