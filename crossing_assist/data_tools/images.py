"""Reading and writing RGB images (OpenCV underneath, RGB order everywhere in the package)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import cv2
import numpy as np

from crossing_assist.data_tools.manifest import atomic_write_bytes
from crossing_assist.errors import UserError
from crossing_assist.geometry import parse_ratio


class ImageError(UserError):
    """An image that cannot be read or written; the message names the path."""


# ISO base media brands of HEIC stills (``ftyp`` box): iPhones save HEIC by default, many
# Android phones can; OpenCV cannot decode them, pillow-heif (libheif) can.
HEIF_BRANDS = frozenset({b"heic", b"heix", b"heim", b"heis", b"hevc", b"hevx", b"hevm", b"hevs", b"mif1", b"msf1"})
# AVIF: OpenCV decodes it but ignores its rotation box; Pillow (with AVIF support) reports the
# turn as the EXIF orientation, which is applied.
AVIF_BRANDS = frozenset({b"avif", b"avis"})


def is_heif(head: bytes) -> bool:
    """Whether a file's first 12 bytes open a HEIC still image (an ``ftyp`` box of a HEIC brand)."""
    return len(head) >= 12 and head[4:8] == b"ftyp" and head[8:12] in HEIF_BRANDS


def _first_line(exc: Exception) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def _load_heif(path: Path) -> np.ndarray:
    """A HEIC/HEIF photo as upright RGB. libheif applies the container's rotation and mirror
    (``irot``/``imir``; iPhones write the same turn in both those and the EXIF orientation, and
    pillow-heif resets the EXIF one), so the pixels come back as displayed: no EXIF turn on top."""
    try:
        import pillow_heif  # noqa: PLC0415 - optional: only HEIC photos need it
    except ImportError:
        raise ImageError(f"{path}: a HEIC/HEIF photo; reading it needs pillow-heif "
                         "(pip install pillow-heif, or the package's [heic] extra)") from None
    try:
        heif = pillow_heif.open_heif(str(path), convert_hdr_to_8bit=True)
        img = np.array(heif, copy=True)   # a view would point into libheif's buffer, freed with ``heif``
    except Exception as exc:  # noqa: BLE001 - libheif's errors vary by version; the path is what matters
        raise ImageError(f"{path}: not a readable HEIC/HEIF image ({_first_line(exc)})") from None
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    return np.ascontiguousarray(img[:, :, :3].astype(np.uint8, copy=False))


def _load_avif(path: Path) -> np.ndarray | None:
    """An AVIF photo upright through Pillow, or None where Pillow cannot read AVIF (then OpenCV
    reads it, unturned)."""
    try:
        from PIL import Image, ImageOps, features  # noqa: PLC0415 - optional: only AVIF needs it
        if not features.check("avif"):
            return None
        with Image.open(path) as im:
            return np.array(ImageOps.exif_transpose(im).convert("RGB"))
    except ImportError:
        return None
    except Exception as exc:  # noqa: BLE001 - a broken file: say so as for any image
        raise ImageError(f"{path}: not a readable AVIF image ({_first_line(exc)})") from None


def load_rgb(path: str | os.PathLike) -> np.ndarray:
    """Read an image file as an H×W×3 uint8 RGB array, as displayed (EXIF orientation applied;
    HEIC/HEIF phone photos through pillow-heif); ImageError naming the path if unreadable."""
    path = Path(path)
    if not path.is_file():
        raise ImageError(f"{path}: image not found")
    data = np.fromfile(str(path), dtype=np.uint8)
    head = data[:12].tobytes()
    if is_heif(head):
        return _load_heif(path)
    if head[4:8] == b"ftyp" and head[8:12] in AVIF_BRANDS:
        img = _load_avif(path)
        if img is not None:
            return img
    img = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    if img is None:
        raise ImageError(f"{path}: not a readable image (empty, truncated or an unknown format)")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def flag_value(flags: tuple[str, ...], key: str) -> str | None:
    """The value of a ``key=value`` manifest flag, or None."""
    for f in flags:
        if f.startswith(key + "="):
            return f[len(key) + 1:]
    return None


def true_aspect(image: np.ndarray, flags: tuple[str, ...] = ()) -> np.ndarray:
    """Undo a squash: an ``aspect=W:H`` flag resizes the frame to that aspect (keeping its
    height) when its pixels say otherwise; frames without the flag are returned as they are."""
    value = flag_value(flags, "aspect")
    if value is None:
        return image
    try:
        aspect = parse_ratio(value)
    except ValueError:
        raise ImageError(f"Invalid flag aspect={value!r}; expected W:H, e.g. aspect=4:3") from None
    h, w = image.shape[:2]
    want = max(1, int(round(h * aspect)))
    if abs(want - w) <= 1:
        return image
    return cv2.resize(image, (want, h), interpolation=cv2.INTER_AREA if want < w else cv2.INTER_LINEAR)


def load_frame(path: str | os.PathLike, flags: tuple[str, ...] = ()) -> np.ndarray:
    """A dataset frame as the camera saw it: :func:`load_rgb` (EXIF orientation applied) then
    :func:`true_aspect` for the row's flags. Frames under 8 px a side or beyond 8:1 raise
    ImageError (a model cannot place a crossing in them)."""
    from crossing_assist.geometry import GeometryError, check_frame_shape

    img = true_aspect(load_rgb(path), flags)
    try:
        check_frame_shape(img.shape[0], img.shape[1])
    except GeometryError as exc:
        raise ImageError(f"{path}: {exc}") from None
    return img


#: After a JPEG scan's entropy-coded data, the next marker: 0xFF (fill bytes may repeat it) then a
#: byte that is not a stuffed zero or a restart marker (RST0-7 sit inside the scan).
_NEXT_MARKER = re.compile(rb"\xff+([^\x00\xd0-\xd7\xff])")


def _jpeg_ends(data: bytes) -> bool:
    """Whether a JPEG's main image reaches its end marker (EOI), walking its segments and scans
    from the start. Data after the EOI is allowed: phones append to their JPEGs (Pixel and
    Samsung motion photos an MP4, depth maps, an MPO's second image)."""
    i, n = 2, len(data)
    while i + 1 < n:
        if data[i] != 0xFF:
            return False                               # not at a marker: corrupt
        while i + 1 < n and data[i + 1] == 0xFF:       # fill bytes
            i += 1
        if i + 1 >= n:
            return False
        marker = data[i + 1]
        if marker == 0xD9:
            return True
        if marker == 0x01 or 0xD0 <= marker <= 0xD7:   # standalone markers
            i += 2
            continue
        if i + 4 > n:
            return False
        end = i + 2 + int.from_bytes(data[i + 2:i + 4], "big")
        if marker == 0xDA:                             # a scan: its coded data runs to the next marker
            m = _NEXT_MARKER.search(data, end)
            if m is None:
                return False
            end = m.start(1) - 1
        i = end
    return False


def _png_ends(data: bytes) -> bool:
    """Whether a PNG's chunks reach IEND whole (data after it allowed)."""
    i, n = 8, len(data)
    while i + 8 <= n:
        length, kind = int.from_bytes(data[i:i + 4], "big"), data[i + 4:i + 8]
        i += 12 + length
        if kind == b"IEND":
            return i <= n
    return False


def check_image_file(path: str | os.PathLike) -> str | None:
    """A check that ``path`` holds a whole image: None when it looks fine, else what is wrong
    ("is empty", "is not an image", "is truncated ..."). JPEG and PNG are walked to their end
    marker (a truncated JPEG still decodes, with a grey bottom, so decoding alone would pass it;
    data a phone appends after the end, e.g. a motion photo's video, is fine); other formats are
    decoded."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except (OSError, ValueError) as exc:
        return f"cannot be read ({getattr(exc, 'strerror', None) or exc})"
    if not data:
        return "is empty"
    if data[:3] == b"\xff\xd8\xff":
        return None if _jpeg_ends(data) else "is truncated (no JPEG end marker)"
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return None if _png_ends(data) else "is truncated (no PNG end chunk)"
    try:
        load_rgb(path)
    except ImageError:
        return "is not a readable image (unknown format or corrupt)"
    return None


def is_square_image(path: str | os.PathLike) -> bool:
    """Whether the image stored at ``path`` is square (any turn keeps a square square). Large
    images are decoded at an eighth of their size (fast for a 12 MP JPEG), which keeps a square
    square and a 4:3 photo 4:3; small ones whole, where rounding could make 6×8 look square."""
    path = Path(path)
    data = np.fromfile(str(path), dtype=np.uint8)
    try:
        img = None if is_heif(data[:12].tobytes()) else cv2.imdecode(data, cv2.IMREAD_REDUCED_GRAYSCALE_8)
    except cv2.error:   # a few pixels a side: nothing left at an eighth
        img = None
    if img is None or min(img.shape[:2]) < 64:
        img = load_rgb(path)
    return img.shape[0] == img.shape[1]


def save_rgb(path: str | os.PathLike, image: np.ndarray, *, quality: int = 92) -> Path:
    """Write an H×W×3 uint8 RGB array atomically; the format follows the suffix (.jpg, .png)."""
    path = Path(path)
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ImageError(f"{path}: expected an H×W×3 uint8 RGB array, got {image.dtype} {image.shape}")
    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)] if path.suffix.lower() in (".jpg", ".jpeg") else []
    ok, buf = cv2.imencode(path.suffix or ".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), params)
    if not ok:
        raise ImageError(f"{path}: OpenCV cannot encode images with suffix {path.suffix!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, buf.tobytes())
    return path
