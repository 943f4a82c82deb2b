"""The image files a character keeps whole, byte for byte, so that an export writes them back unchanged.

An avatar's file holds images the character does not draw from (normal,
metal/roughness, occlusion, emissive and MToon textures, the thumbnail).
They are kept as the file had them (PNG or JPEG, never decoded nor
re-encoded) in two sections of the ``character`` table: ``kept_image_bytes``
(all images, one after the other) and ``kept_image_offsets`` (where each
starts, and the end). A 4096² normal map of fine detail is a PNG of some
tens of MB, so the bounds are :data:`MAX_IMAGE_BYTES` per image and
:data:`MAX_TOTAL_BYTES` in all; the total is the section's bound in the
tables file, checked from its header before anything is allocated. What
each image is for (its place in the file, name, type) is JSON beside the
glTF parts kept for export (``settings.source.kept.images``, each entry's
``index`` the image here).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facepuppet.runtime.files.tables import Section, TablesError

MAX_IMAGE_BYTES = 32 << 20  # one kept image: a 4096² PNG normal map of noise-like detail fits
MAX_TOTAL_BYTES = 64 << 20  # all kept images of one character together

SECTIONS = {
    "kept_image_offsets": Section("int64", ("n_kept_images+1",), "byte offset of each kept image, and the end",
                                  optional=True),
    "kept_image_bytes": Section("uint8", ("n_kept_bytes",), "the kept image files' bytes (PNG, JPEG) as the "
                                "file had them", optional=True, max_bytes=MAX_TOTAL_BYTES),
}


@dataclass(frozen=True, eq=False)
class KeptImages:
    """Image files kept whole.

    Attributes
    ----------
    offsets : ndarray (n_kept_images + 1,) int64, image i is ``data[offsets[i]:offsets[i + 1]]``
    data : ndarray (n_kept_bytes,) uint8
    """

    offsets: np.ndarray
    data: np.ndarray

    @classmethod
    def of(cls, images: list[bytes]) -> KeptImages:
        """The kept images of byte strings ``images`` (checked against the bounds)."""
        offsets = np.cumsum([0] + [len(b) for b in images]).astype(np.int64)
        out = cls(offsets, np.frombuffer(b"".join(images), np.uint8).copy())
        out.check()
        return out

    def check(self) -> None:
        """Refuse offsets that do not cut ``data`` into images, and an image or a total past the bounds
        (TablesError naming the section)."""
        o, d = self.offsets, self.data
        if o.ndim != 1 or len(o) < 1 or d.ndim != 1:
            raise TablesError(None, "kept_image_offsets", f"expected (n + 1,) offsets and (n_bytes,) bytes, found "
                                                          f"{o.shape} and {d.shape}")
        if d.nbytes > MAX_TOTAL_BYTES:
            raise TablesError(None, "kept_image_bytes", f"{d.nbytes} bytes of kept images, more than the limit of "
                                                        f"{MAX_TOTAL_BYTES} bytes")
        if o[0] != 0 or o[-1] != len(d) or np.any(np.diff(o) < 0):
            raise TablesError(None, "kept_image_offsets", f"must start at 0, never decrease and end at the "
                                                          f"{len(d)} bytes of kept_image_bytes")
        sizes = np.diff(o)
        if len(sizes) and int(sizes.max()) > MAX_IMAGE_BYTES:
            i = int(np.argmax(sizes))
            raise TablesError(None, "kept_image_offsets", f"kept image {i} is {int(sizes[i])} bytes, more than the "
                                                          f"limit of {MAX_IMAGE_BYTES} bytes per image")
        o.setflags(write=False)
        d.setflags(write=False)

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def image(self, i: int) -> bytes:
        """The bytes of kept image ``i``."""
        return self.data[int(self.offsets[i]):int(self.offsets[i + 1])].tobytes()
