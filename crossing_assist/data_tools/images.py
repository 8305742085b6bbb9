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


def iso_brand(head: bytes) -> bytes | None:
    """The major brand of an ISO base media file (HEIC, AVIF) from its first 12 bytes, else None."""
    return head[8:12] if len(head) >= 12 and head[4:8] == b"ftyp" else None


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
    brand = iso_brand(data[:12].tobytes())
    if brand in HEIF_BRANDS:
        return _load_heif(path)
    if brand in AVIF_BRANDS:
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


def frame_fov(flags: tuple[str, ...]) -> float | None:
    """The camera's horizontal FOV (degrees) an ``fov=DEG`` manifest flag gives the frame (e.g. from
    ``crossing-data frames --fov``), or None (the bundle's default for the frame's orientation).
    ImageError for a value that is not a FOV in 20..170 degrees."""
    from crossing_assist.geometry import GeometryError, check_fov

    value = flag_value(flags, "fov")
    if value is None:
        return None
    try:
        return check_fov(value)
    except GeometryError as exc:
        raise ImageError(f"flag fov={value}: {exc}") from None


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


#: JPEG start-of-frame markers (0xC0-0xCF but DHT 0xC4, JPG 0xC8, DAC 0xCC): they hold the size.
_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def _jpeg_walk(data: bytes) -> tuple[bool, tuple[int, int] | None]:
    """Whether a JPEG's main image reaches its end marker (EOI), walking its segments and scans
    from the start, and its (height, width) from its frame header. Data after the EOI is allowed:
    phones append to their JPEGs (Pixel and Samsung motion photos an MP4, depth maps, an MPO's
    second image)."""
    i, n, size = 2, len(data), None
    while i + 1 < n:
        if data[i] != 0xFF:
            return False, size                         # not at a marker: corrupt
        while i + 1 < n and data[i + 1] == 0xFF:       # fill bytes
            i += 1
        if i + 1 >= n:
            return False, size
        marker = data[i + 1]
        if marker == 0xD9:
            return True, size
        if marker == 0x01 or 0xD0 <= marker <= 0xD7:   # standalone markers
            i += 2
            continue
        if i + 4 > n:
            return False, size
        end = i + 2 + int.from_bytes(data[i + 2:i + 4], "big")
        if marker in _SOF and size is None and i + 9 <= n:
            size = int.from_bytes(data[i + 5:i + 7], "big"), int.from_bytes(data[i + 7:i + 9], "big")
        if marker == 0xDA:                             # a scan: its coded data runs to the next marker
            m = _NEXT_MARKER.search(data, end)
            if m is None:
                return False, size
            end = m.start(1) - 1
        i = end
    return False, size


def _png_walk(data: bytes) -> tuple[bool, tuple[int, int] | None]:
    """Whether a PNG's chunks reach IEND whole (data after it allowed), and its (height, width)
    from its header chunk."""
    size = (int.from_bytes(data[20:24], "big"), int.from_bytes(data[16:20], "big")) if len(data) >= 24 else None
    i, n = 8, len(data)
    while i + 8 <= n:
        length, kind = int.from_bytes(data[i:i + 4], "big"), data[i + 4:i + 8]
        i += 12 + length
        if kind == b"IEND":
            return i <= n, size
    return False, size


def inspect_image_file(path: str | os.PathLike) -> tuple[str | None, tuple[int, int] | None]:
    """``(problem, size)``, one read of the file: what is wrong with it (None when it holds a whole
    image: "is empty", "is not an image", "is truncated ...") and, when whole, the image's
    (height, width) as stored (JPEG, PNG) or decoded (other formats; a turn swaps the two, which
    keeps a square square). JPEG and PNG are walked to their end marker (a truncated JPEG still
    decodes, with a grey bottom, so decoding alone would pass it; data a phone appends after the
    end, e.g. a motion photo's video, is fine); other formats are decoded."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except (OSError, ValueError) as exc:
        return f"cannot be read ({getattr(exc, 'strerror', None) or exc})", None
    if not data:
        return "is empty", None
    if data[:3] == b"\xff\xd8\xff":
        whole, size = _jpeg_walk(data)
        if not whole:
            return "is truncated (no JPEG end marker)", None
        return (None, size) if size else ("is not a readable image (no JPEG frame header)", None)
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        whole, size = _png_walk(data)
        return (None, size) if whole else ("is truncated (no PNG end chunk)", None)
    try:
        return None, load_rgb(path).shape[:2]
    except ImageError:
        return "is not a readable image (unknown format or corrupt)", None


def check_image_file(path: str | os.PathLike) -> str | None:
    """What is wrong with the image file at ``path``, or None (:func:`inspect_image_file`)."""
    return inspect_image_file(path)[0]


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
