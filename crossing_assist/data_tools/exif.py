"""A photo's own camera from its EXIF: the field of view its strips are headings in.

Phones write the lens's 35 mm-equivalent focal length (EXIF ``FocalLengthIn35mmFilm``, tag
0xA405) into every photo: 26 mm for most main cameras, 13-16 mm for an ultra-wide, 52-77 mm for a
2-3x telephoto. The equivalent is matched on the diagonal (a full 36 x 24 mm frame's, 43.27 mm),
so a photo of aspect ``a`` (width / height, as displayed) sees horizontally

    fov = 2 atan(43.27 a / sqrt(1 + a^2) / (2 f))

A 26 mm 4:3 photo: 67.3 deg in landscape, 53.1 deg in portrait, the bundles' defaults for the two
orientations. A telephoto's photo is narrower and an ultra-wide's wider: read at the default, its
strips would be turned into the wrong headings and the model shown it at the wrong scale.

The focal length describes the image the camera recorded, whose size phones write too
(``PixelXDimension`` / ``PixelYDimension``). A photo cropped afterwards to another aspect keeps that
EXIF: it is taken as the largest centred crop of the recorded image, as
:func:`~crossing_assist.geometry.default_fov` takes a frame narrower than the sensor. A square cut
from a 26 mm 4:3 photo keeps its height and sees 53.1 deg across, where the square's own diagonal
would say 60.9 deg; a 16:9 cut keeps its width, 67.3 deg (71.9). A crop that keeps the aspect
cannot be told from a smaller copy and is read as the whole photo.

Read without Pillow (JPEG: its APP1 segment; HEIC/HEIF: through pillow-heif, which reading HEIC
needs anyway). Anything missing, malformed or outside the FOVs the geometry accepts gives None
(the bundle's default for the frame's orientation), never an error: EXIF is a hint, not a label.
"""

from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass
from pathlib import Path

from crossing_assist.data_tools.images import HEIF_BRANDS, iso_brand
from crossing_assist.geometry import GeometryError, check_fov, default_fov

#: The diagonal of a 36 x 24 mm frame, mm: what a 35 mm-equivalent focal length is matched on.
FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)
_ORIENTATION, _EXIF_IFD, _FOCAL_35MM = 0x0112, 0x8769, 0xA405
_PIXEL_X, _PIXEL_Y = 0xA002, 0xA003     # the recorded image's width and height, as stored
_SHORT, _LONG = 3, 4        # the types these tags come in


def equivalent_fov(focal_35mm: float, aspect: float) -> float:
    """Horizontal FOV (degrees) of a photo of ``aspect`` (width / height, as displayed) taken at
    ``focal_35mm`` (mm, 35 mm-equivalent, matched on the diagonal)."""
    if not (focal_35mm > 0 and aspect > 0):
        raise ValueError(f"Invalid focal length {focal_35mm} mm or aspect {aspect}; both must be > 0")
    width_mm = FULL_FRAME_DIAGONAL_MM * aspect / math.hypot(aspect, 1.0)
    return math.degrees(2 * math.atan(width_mm / (2 * focal_35mm)))


def _jpeg_exif(data: bytes) -> bytes | None:
    """The TIFF block of a JPEG's EXIF APP1 segment (before its first scan), or None."""
    i, n = 2, len(data)
    while i + 4 <= n and data[i] == 0xFF:
        marker = data[i + 1]
        if marker == 0xFF:                      # fill byte
            i += 1
            continue
        if marker == 0xDA or marker == 0xD9:    # the first scan, or the end: no EXIF before it
            return None
        end = i + 2 + int.from_bytes(data[i + 2:i + 4], "big")
        if marker == 0xE1 and data[i + 4:i + 10] == b"Exif\0\0":
            return data[i + 10:min(end, n)]
        i = end
    return None


def _heif_exif(path: Path) -> bytes | None:
    """The TIFF block of a HEIC/HEIF photo's EXIF (pillow-heif), or None."""
    try:
        import pillow_heif  # noqa: PLC0415 - optional: only HEIC photos need it
        raw = pillow_heif.open_heif(str(path)).info.get("exif")
    except Exception:  # noqa: BLE001 - no pillow-heif or an unreadable file: no hint
        return None
    if not raw:
        return None
    return raw[6:] if raw[:6] == b"Exif\0\0" else raw


def exif_tags(tiff: bytes) -> dict[int, int]:
    """The orientation (0x0112), 35 mm-equivalent focal length (0xA405) and recorded width and
    height (0xA002, 0xA003) of an EXIF TIFF block, those present and readable; {} for a block that
    is not one."""
    if len(tiff) < 8 or tiff[:2] not in (b"II", b"MM"):
        return {}
    end = "<" if tiff[:2] == b"II" else ">"

    def entries(offset: int):
        if not 0 < offset <= len(tiff) - 2:
            return
        (count,) = struct.unpack_from(end + "H", tiff, offset)
        for k in range(count):
            at = offset + 2 + 12 * k
            if at + 12 > len(tiff):
                return
            tag, kind, n = struct.unpack_from(end + "HHI", tiff, at)
            if kind in (_SHORT, _LONG) and n == 1:   # one value, held in the entry itself
                yield tag, struct.unpack_from(end + ("H" if kind == _SHORT else "I"), tiff, at + 8)[0]

    (ifd0,) = struct.unpack_from(end + "I", tiff, 4)
    found: dict[int, int] = {}
    for tag, value in entries(ifd0):
        if tag == _ORIENTATION:
            found[tag] = value
        elif tag == _EXIF_IFD:
            found.update((t, v) for t, v in entries(value) if t in (_FOCAL_35MM, _PIXEL_X, _PIXEL_Y))
    return found


@dataclass(frozen=True)
class ExifCamera:
    """What a photo's EXIF says of its camera: ``focal_35mm`` (mm, 35 mm-equivalent; None: not
    written, or 0, "unknown"); ``turned``, whether its stored pixels are turned a quarter (a JPEG's
    EXIF orientation 5-8; libheif turns a HEIC upright itself); ``recorded``, the (width, height)
    of the image the camera recorded, as stored (None: not written)."""

    focal_35mm: float | None = None
    turned: bool = False
    recorded: tuple[int, int] | None = None

    def fov(self, aspect: float) -> float | None:
        """Horizontal FOV (degrees) of the photo, or of a view of it, ``aspect`` (width / height) as
        displayed: the recorded image's FOV from the focal length, cut to ``aspect`` as its largest
        centred crop (the module's docstring); without a recorded size, the focal length matched
        on ``aspect``'s own diagonal. None for no focal length or a FOV outside 20..170 deg."""
        if not self.focal_35mm or not aspect > 0:
            return None
        # long / short side of the recorded image, either way up (unknown: the view is the whole image)
        full = max(self.recorded) / min(self.recorded) if self.recorded else max(aspect, 1 / aspect)
        whole = (equivalent_fov(self.focal_35mm, full), equivalent_fov(self.focal_35mm, 1 / full))
        try:
            return check_fov(default_fov(aspect, 1.0, whole, sensor_aspect=full))
        except GeometryError:
            return None


def read_camera(path: str | os.PathLike) -> ExifCamera:
    """The :class:`ExifCamera` of the photo at ``path`` (JPEG: its APP1 segment; HEIC/HEIF: through
    pillow-heif); an empty one for a file without EXIF, or one that cannot be read."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 17)   # an APP1 segment is at most 64 KiB, after APP0 and the like
    except OSError:
        return ExifCamera()
    heif = iso_brand(head[:12]) in HEIF_BRANDS
    tiff = _heif_exif(path) if heif else _jpeg_exif(head) if head[:3] == b"\xff\xd8\xff" else None
    tags = exif_tags(tiff) if tiff else {}
    w, h = tags.get(_PIXEL_X, 0), tags.get(_PIXEL_Y, 0)
    return ExifCamera(focal_35mm=float(tags[_FOCAL_35MM]) if tags.get(_FOCAL_35MM) else None,
                      turned=not heif and tags.get(_ORIENTATION, 1) in (5, 6, 7, 8),
                      recorded=(w, h) if w > 0 and h > 0 else None)


def photo_fov(path: str | os.PathLike, size: tuple[int, int], aspect: float | None = None) -> float | None:
    """The horizontal FOV (degrees) of the photo at ``path`` as displayed, from its EXIF
    (:meth:`ExifCamera.fov`), or None where it gives none (or one outside 20..170 deg).
    ``size``: its (height, width) as stored (a JPEG's EXIF orientation 5-8 turns it) or, for
    HEIC, as decoded (upright), as :func:`~crossing_assist.data_tools.images.inspect_image_file`
    gives it; ``aspect`` (width / height), where the pixels do not say it (a squashed copy's
    ``aspect=W:H`` flag), wins."""
    camera = read_camera(path)
    h, w = size[::-1] if camera.turned else size
    if not (h > 0 and w > 0):
        return None
    return camera.fov(aspect or w / h)
