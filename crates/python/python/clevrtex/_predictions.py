"""`clevrtex.write_predictions`: a batch of a model's masks (and reconstructions) written under
the names `clevrtex eval` finds them by (docs/eval.md): `<stem>_mask.png` and
`<stem>_recon.png`, or `<stem>.npz` with `labels` (and `recon`). NumPy only: the PNGs are
written here (8-bit grey ids, 16-bit when an id is over 255; 8-bit RGB reconstructions)."""

import os
import stat
import struct
import zlib
from typing import Any, List, Optional, Sequence

import numpy as np


def _array(x: Any, what: str) -> np.ndarray:
    for step in ("detach", "cpu", "numpy"):  # a torch tensor, without importing torch
        if hasattr(x, step):
            x = getattr(x, step)()
    a = np.asarray(x)
    if a.dtype.kind not in "biuf":
        raise ValueError(f"`{what}` holds {a.dtype} values, not numbers")
    return a


def _ids(masks: Any) -> np.ndarray:
    """(B, H, W) ids from integer ids (B, H, W) / (B, 1, H, W) or soft masks (B, K, H, W) /
    (B, K, 1, H, W) (argmax over K, first index on ties, as `clevrtex eval` takes them)."""
    m = _array(masks, "masks")
    if m.dtype.kind in "biu":
        if m.ndim == 4 and m.shape[1] == 1:
            m = m[:, 0]
        if m.ndim != 3:
            raise ValueError(f"integer `masks` must be (B, H, W) or (B, 1, H, W) ids, not {m.shape}")
        if m.size and (m.min() < 0 or m.max() > 65535):
            raise ValueError(f"`masks` holds ids from {m.min()} to {m.max()}: ids are 0 to 65535")
        return m.astype(np.uint16 if m.size and m.max() > 255 else np.uint8)
    if m.ndim == 5 and m.shape[2] == 1:
        m = m[:, :, 0]
    if m.ndim != 4:
        raise ValueError(f"float `masks` must be (B, K, H, W) or (B, K, 1, H, W) soft masks, not {m.shape}")
    if not np.isfinite(m).all():
        raise ValueError("`masks` holds NaN or infinite values")
    if m.shape[1] > 65536:
        raise ValueError(f"`masks` has {m.shape[1]} slots, more than 65536")
    ids = m.argmax(axis=1)
    return ids.astype(np.uint16 if m.shape[1] > 256 else np.uint8)


def _png(a: np.ndarray) -> bytes:
    """A PNG of the (H, W) grey (8 or 16 bits) or (H, W, 3) 8-bit RGB array `a`."""
    h, w = a.shape[:2]
    bits = 16 if a.dtype == np.uint16 else 8
    colour = 2 if a.ndim == 3 else 0
    raw = np.ascontiguousarray(a.astype(">u2" if bits == 16 else "u1")).reshape(h, -1).view(np.uint8)
    data = b"".join(b"\x00" + row.tobytes() for row in raw)

    def chunk(t: bytes, d: bytes) -> bytes:
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)

    head = struct.pack(">IIBBBBB", w, h, bits, colour, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", head) + chunk(b"IDAT", zlib.compress(data, 6)) + chunk(b"IEND", b"")


def _link_refused(path: str) -> ValueError:
    return ValueError(f"`{path}` is a symbolic link; predictions are not written through a link\nhint: remove the link, or write into another folder")


def _open_folder(out_dir: str) -> int:
    """A handle on `out_dir` (created if missing), refused when it is a symbolic link."""
    if os.path.islink(out_dir):
        raise _link_refused(out_dir)
    os.makedirs(out_dir, exist_ok=True)
    try:
        return os.open(out_dir, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
    except OSError as e:
        if os.path.islink(out_dir):  # swapped for a link since the check
            raise _link_refused(out_dir) from e
        raise


def _write(folder: int, name: str, data: bytes) -> None:
    """`data` as `name` in the folder `folder` (a handle), as clevrtex's own writers write
    (docs/security.md): a temporary beside it created exclusively without following a link
    (another name is tried when something sits there), synced and renamed over `name`; the
    temporary is removed on every error path."""
    for attempt in range(100):
        tmp = f".{name}.{os.getpid()}.{attempt}.clevrtex-tmp"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o666, dir_fd=folder)
            break
        except FileExistsError:
            continue
    else:
        raise FileExistsError(f"no free temporary name for `{name}`")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.rename(tmp, name, src_dir_fd=folder, dst_dir_fd=folder)
    except BaseException:
        try:
            os.unlink(tmp, dir_fd=folder)
        except FileNotFoundError:
            pass
        raise


def write_predictions(
    out_dir: str,
    stems: Sequence[str],
    masks: Any,
    recon: Optional[Any] = None,
    format: str = "png",
) -> List[str]:
    """Write a batch of predictions into `out_dir` (created if missing) under the names
    `clevrtex eval PREDS GT` reads: for each `stems[b]` (an item's `stem`, from
    `Dataset(...)[i]`'s metadata or dict, or `Dataset.stem(i)`), `<stem>_mask.png` (and
    `<stem>_recon.png` with `recon`) with `format="png"`, or `<stem>.npz` (`labels`, and
    `recon` as float32 (3, H, W)) with `format="npz"`.

    `masks`: `(B, H, W)` or `(B, 1, H, W)` integer ids, or `(B, K, H, W)` / `(B, K, 1, H, W)`
    soft masks (argmax over K); `recon`: `(B, 3, H, W)` or `(B, H, W, 3)` floats in [0, 1]
    (the PNG rounds them to 8 bits, the `.npz` keeps them). numpy arrays or torch tensors.
    Returns the paths written. A stem that is not a plain file name, or arrays of the wrong
    shape, are a ValueError naming them; nothing is written then. Each file is written as
    clevrtex's own writers write (a temporary beside it, synced and renamed over it); a
    symbolic link as `out_dir` or at a file's name is refused (ValueError), never written
    through."""
    if format not in ("png", "npz"):
        raise ValueError(f"unknown format `{format}`; known: png, npz")
    if isinstance(stems, str):
        raise ValueError("`stems` is one string; give a list of one stem per image")
    stems = list(stems)
    for s in stems:
        if not isinstance(s, str) or not s or s in (".", "..") or "/" in s or os.sep in s or "\0" in s:
            raise ValueError(f"stem {s!r} is not a plain file name (e.g. `CLEVRTEX_full_000012`)")
    ids = _ids(masks)
    if ids.shape[0] != len(stems):
        raise ValueError(f"{len(stems)} stems for {ids.shape[0]} masks")
    rec = None
    if recon is not None:
        rec = _array(recon, "recon").astype(np.float32)
        if rec.ndim == 4 and rec.shape[1] == 3 and rec.shape[-1] != 3:
            rec = rec.transpose(0, 2, 3, 1)
        if rec.shape != ids.shape + (3,):
            raise ValueError(f"`recon` is {_array(recon, 'recon').shape}; expected (B, 3, H, W) or (B, H, W, 3) with (B, H, W) = {ids.shape}")
    exts = (".npz",) if format == "npz" else ("_mask.png", "_recon.png") if rec is not None else ("_mask.png",)
    names = [stem + ext for stem in stems for ext in exts]
    folder = _open_folder(out_dir)
    try:
        for name in names:
            try:
                link = stat.S_ISLNK(os.lstat(name, dir_fd=folder).st_mode)
            except FileNotFoundError:
                link = False
            if link:
                raise _link_refused(os.path.join(out_dir, name))
        for b, stem in enumerate(stems):
            if format == "npz":
                import io

                buf = io.BytesIO()
                arrays = {"labels": ids[b]}
                if rec is not None:
                    arrays["recon"] = rec[b].transpose(2, 0, 1)
                np.savez_compressed(buf, **arrays)
                _write(folder, stem + ".npz", buf.getvalue())
                continue
            _write(folder, stem + "_mask.png", _png(ids[b]))
            if rec is not None:
                rgb = np.clip(np.round(rec[b] * 255.0), 0, 255).astype(np.uint8)
                _write(folder, stem + "_recon.png", _png(rgb))
        os.fsync(folder)
    finally:
        os.close(folder)
    written = [os.path.join(out_dir, n) for n in names]
    return written
