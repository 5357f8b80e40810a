"""The images of a glTF file that trimesh does not decode for rtmesh: those of the KHR
material extensions' textures (trimesh keeps the core material's five).  An image's bytes
come from a data URI, a file beside a ``.gltf``, or a buffer view (a GLB's binary chunk, or
a buffer's own URI); PIL decodes them.
"""

import base64
import io
import os
import struct
import urllib.parse

from PIL import Image

from rtmesh.core.errors import MeshError

_GLB_MAGIC = 0x46546C67  # "glTF"
_BIN_CHUNK = 0x004E4942  # "BIN\0"


class GltfImages:
    """Decoded images of one glTF file, by image index (each decoded once).

    Parameters
    ----------
    path : str
        The ``.gltf`` or ``.glb`` file (relative URIs are resolved against its folder).
    doc : dict
        Its JSON.
    """

    def __init__(self, path, doc):
        self.path, self.doc = os.fspath(path), doc
        self._buffers, self._images = {}, {}

    def image(self, index, label):
        """The PIL image of ``doc["images"][index]``.

        Raises
        ------
        MeshError
            One line naming ``label`` and the image: missing, out of range or undecodable.
        """
        if index not in self._images:
            try:
                data = self._bytes(self.doc["images"][index])
                image = Image.open(io.BytesIO(data))
                image.load()
            except (KeyError, IndexError, TypeError, ValueError, OSError, struct.error) as exc:
                raise MeshError(f"{os.path.basename(self.path)}: {label}: image {index!r} is missing or "
                                f"unreadable ({exc})") from None
            self._images[index] = image
        return self._images[index]

    def _bytes(self, image):
        """The encoded bytes of an image object."""
        if "bufferView" in image:
            view = self.doc["bufferViews"][image["bufferView"]]
            buffer = self._buffer(view["buffer"])
            start = view.get("byteOffset", 0)
            end = start + view["byteLength"]
            if end > len(buffer):
                raise ValueError("its buffer view runs past the buffer")
            return buffer[start:end]
        return self._uri(image["uri"])

    def _uri(self, uri):
        """The bytes a URI names: a base64 data URI or a file beside the glTF."""
        if uri.startswith("data:"):
            return base64.b64decode(uri.split(",", 1)[1])
        folder = os.path.dirname(os.path.abspath(self.path))
        with open(os.path.join(folder, urllib.parse.unquote(uri)), "rb") as f:
            return f.read()

    def _buffer(self, index):
        """The bytes of ``doc["buffers"][index]`` (a GLB's binary chunk when it has no URI)."""
        if index not in self._buffers:
            entry = self.doc["buffers"][index]
            if "uri" in entry:
                self._buffers[index] = self._uri(entry["uri"])
            else:
                self._buffers[index] = _glb_binary(self.path)
        return self._buffers[index]


def _glb_binary(path):
    """The binary chunk of a GLB file."""
    with open(path, "rb") as f:
        data = f.read()
    magic, _, _ = struct.unpack_from("<III", data, 0)
    if magic != _GLB_MAGIC:
        raise ValueError("not a GLB file")
    length, _ = struct.unpack_from("<II", data, 12)
    offset = 20 + length
    chunk_length, kind = struct.unpack_from("<II", data, offset)
    if kind != _BIN_CHUNK:
        raise ValueError("the GLB has no binary chunk")
    return data[offset + 8:offset + 8 + chunk_length]
