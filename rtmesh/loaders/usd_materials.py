"""USD materials to rtmesh's: ``UsdPreviewSurface`` (with ``UsdUVTexture`` textures read
through ``UsdPrimvarReader_float2``) mapped onto the glTF metallic-roughness model that
glTF files load as (:func:`rtmesh.loaders.gltf_materials.gltf_material`), and the
``displayColor`` material of a prim without one; textures read from files or from inside a
USDZ package."""

import io
import logging
import os

import numpy as np
import trimesh

from rtmesh.core.errors import MeshError
from rtmesh.io.texture_images import (MAX_TEXTURE_PIXELS, Texture, check_texture_size, image_size_guard,
                                      load_texture)
from rtmesh.loaders.gltf_materials import OPTIONS_KEY, gltf_material
from rtmesh.loaders.mesh_files import check_file
from rtmesh.loaders.usd_stage import usd_array, usd_number

# the largest texture file read (a float RGBA image of MAX_TEXTURE_PIXELS, uncompressed)
MAX_TEXTURE_BYTES = 16 * MAX_TEXTURE_PIXELS

log = logging.getLogger(__name__)

# texture roles whose EXR or HDR texels are kept as floats (the Material's attribute of each)
_FLOAT_ROLES = {"baseColorTexture": "diffuse_texture", "emissiveTexture": "emission_texture",
                "normalTexture": "normal_texture"}


class _FloatImage:
    """An EXR or HDR texture's linear texels (h, w, c) where a PIL image would be: read by
    :func:`rtmesh.io.texture_images.load_texture` (OpenImageIO; NaN, infinite and negative
    texels refused), placed in the material after :func:`gltf_material` built it."""

    def __init__(self, pixels):
        self.pixels = np.asarray(pixels, dtype=np.float64)
        if self.pixels.ndim == 2:
            self.pixels = self.pixels[:, :, None]

    def channel(self, index):
        pixels = self.pixels
        if index < pixels.shape[2]:
            return _FloatImage(pixels[:, :, index])
        return _FloatImage(np.ones(pixels.shape[:2]) if index == 3 else pixels[:, :, :1])

    def rgb(self):
        """Three or four channels, as Texture.from_pil gives for a PIL image."""
        pixels = self.pixels
        return pixels if pixels.shape[2] in (3, 4) else np.repeat(pixels[:, :, :1], 3, axis=2)

    def to_pil(self):
        """The first channel as an 8-bit PIL image (a weight: roughness, metalness)."""
        from PIL import Image

        return Image.fromarray((np.clip(self.pixels[:, :, 0], 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8), "L")


_WRAP = {"repeat": "repeat", "mirror": "mirror", "clamp": "clamp", "black": "clamp", "useMetadata": "repeat"}


class UsdMaterialReader:
    """The USD reader's materials: each bound material (or display colour) read once.

    A part of the reader (:class:`rtmesh.loaders.usd_files._Reader`): materials join its
    ``content.materials``, indexed by path or display colour in ``material_ids``; shaders'
    inputs are read at the reader's ``time``, texture names are reported with its ``path``.
    """

    def _material(self, prim):
        """(bound UsdShade.Material or None, the texture-coordinate primvar its textures read)."""
        bound = self.UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        if not bound:
            return None, "st"
        return bound, self._uv_name(bound) or "st"

    def _uv_name(self, material):
        for shader in self._shaders(material):
            if shader.GetIdAttr().Get() == "UsdPrimvarReader_float2":
                value = self._input_value(shader, "varname")
                if value:
                    return str(value)
        return None

    def _shaders(self, material):
        out = []
        for prim in self.Usd.PrimRange(material.GetPrim()):
            if prim.IsA(self.UsdShade.Shader):
                out.append(self.UsdShade.Shader(prim))
        return out

    def _input_value(self, shader, name):
        """An input's value through connections to material interface inputs; None unset."""
        shade_input = shader.GetInput(name)
        if not shade_input:
            return None
        for attribute in shade_input.GetValueProducingAttributes():
            if self.UsdShade.Input.IsInput(attribute):
                return attribute.Get(self.time)
        return None

    def _texture_source(self, shader, name):
        """(UsdUVTexture shader, output name) an input is connected to, or None."""
        shade_input = shader.GetInput(name)
        if not shade_input:
            return None
        for attribute in shade_input.GetValueProducingAttributes():
            if self.UsdShade.Output.IsOutput(attribute):
                source = self.UsdShade.Shader(attribute.GetPrim())
                if source.GetIdAttr().Get() == "UsdUVTexture":
                    return source, self.UsdShade.Output(attribute).GetBaseName()
        return None

    def _material_index(self, material, prim):
        UsdGeom = self.UsdGeom
        if material is None:
            primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor")
            colour = self._primvar(primvar, dict(point=np.zeros((1, 3), int), faces=1, points=1, corners=1,
                                                 face=np.zeros(1, int), corner=np.zeros((1, 3), int)), 3, "colour")
            base = (0.18, 0.18, 0.18) if colour is None else tuple(float(c) for c in colour[0, 0])
            if colour is not None and primvar.GetInterpolation() != UsdGeom.Tokens.constant:
                base = (1.0, 1.0, 1.0)  # the vertex colours carry it (glTF's COLOR_0 times the base)
            key = ("displayColor", base)
            if key not in self.material_ids:
                pbr = trimesh.visual.material.PBRMaterial(
                    name=f"displayColor {base}", baseColorFactor=[*base, 1.0], metallicFactor=0.0,
                    roughnessFactor=0.5)
                self._add_material(key, gltf_material(pbr, {"name": pbr.name}, pbr.name, self.path))
            return self.material_ids[key]
        key = str(material.GetPath())
        if key not in self.material_ids:
            self._add_material(key, self._preview_surface(material))
        return self.material_ids[key]

    def _add_material(self, key, material):
        self.material_ids[key] = len(self.content.materials)
        self.content.materials.append(material)

    def _preview_surface(self, material):
        """A UsdPreviewSurface as the glTF metallic-roughness material."""
        name = material.GetPrim().GetName()
        shader = None
        source = material.ComputeSurfaceSource()
        if source and source[0]:
            shader = source[0]
        if shader is None or shader.GetIdAttr().Get() != "UsdPreviewSurface":
            self._skip("materials without a UsdPreviewSurface (grey used)", material.GetPrim())
            pbr = trimesh.visual.material.PBRMaterial(name=name, baseColorFactor=[0.18, 0.18, 0.18, 1.0],
                                                      metallicFactor=0.0, roughnessFactor=0.5)
            return gltf_material(pbr, {"name": name}, name, self.path)

        from rtmesh.loaders.scene_keys import _float, _non_negative

        def number(key, default, reader=_non_negative):
            value = self._input_value(shader, key)
            return default if value is None else usd_number(value, f"{self.path}: {shader.GetPath()}.inputs:{key}",
                                                            reader)

        def colour(key, default):
            value = self._input_value(shader, key)
            return list(default) if value is None else list(_colour(value, f"{self.path}: {shader.GetPath()}.inputs:{key}"))

        if number("useSpecularWorkflow", 0.0, _float):
            self._skip("materials in the specular workflow (read as metallic-roughness)", material.GetPrim())
        opacity = number("opacity", 1.0)
        threshold = number("opacityThreshold", 0.0)
        options, images = {}, {}
        base = colour("diffuseColor", (0.18, 0.18, 0.18))
        emissive = colour("emissiveColor", (0.0, 0.0, 0.0))
        metallic, roughness = number("metallic", 0.0), number("roughness", 0.5)

        floats = {}

        def placed(role, found):
            """A PIL image for trimesh's material: an EXR's texels wait in ``floats``."""
            image = found[0]
            if isinstance(image, _FloatImage):
                from PIL import Image

                floats[role] = (image, found[1])
                return Image.new("RGB", (1, 1))
            return image

        diffuse = self._texture(shader, "diffuseColor", name)
        if diffuse is not None:
            images["baseColorTexture"], options["baseColorTexture"], scale = placed("baseColorTexture", diffuse), \
                diffuse[1], diffuse[2]
            base = list(scale[:3])
        emission = self._texture(shader, "emissiveColor", name)
        if emission is not None:
            images["emissiveTexture"], options["emissiveTexture"], scale = placed("emissiveTexture", emission), \
                emission[1], emission[2]
            emissive = list(scale[:3])
        normal = self._texture(shader, "normal", name)
        if normal is not None:
            images["normalTexture"], options["normalTexture"] = placed("normalTexture", normal), normal[1]
        rough, metal = self._texture(shader, "roughness", name), self._texture(shader, "metallic", name)
        if rough is not None or metal is not None:
            images["metallicRoughnessTexture"], options["metallicRoughnessTexture"] = _packed(rough, metal)
            roughness = 1.0 if rough is not None else roughness
            metallic = 1.0 if metal is not None else metallic
        mode = "OPAQUE"
        if threshold > 0.0:
            mode = "MASK"
        elif opacity < 1.0:
            mode = "BLEND"
        pbr = trimesh.visual.material.PBRMaterial(
            name=name, baseColorFactor=[*base, opacity], metallicFactor=metallic, roughnessFactor=roughness,
            emissiveFactor=emissive, alphaMode=mode, alphaCutoff=threshold if threshold > 0.0 else None,
            doubleSided=True, **images)
        json_material = {"name": name, "pbrMetallicRoughness": {"baseColorFactor": [*base, opacity],
                                                                "metallicFactor": metallic,
                                                                "roughnessFactor": roughness},
                         "emissiveFactor": emissive, "alphaMode": mode, "doubleSided": True,
                         OPTIONS_KEY: options}
        if threshold > 0.0:
            json_material["alphaCutoff"] = threshold
        result = gltf_material(pbr, json_material, name, self.path)
        for role, (image, texture_options) in floats.items():
            if getattr(result, _FLOAT_ROLES[role], None) is not None:
                setattr(result, _FLOAT_ROLES[role], Texture(image.rgb(), name=f"{name} {role}", **texture_options))
        return result

    def _texture(self, shader, key, material_name):
        """(PIL image of the channels the input reads, texture options, scale (4,)) of a
        UsdUVTexture connected to ``key``, or None."""
        found = self._texture_source(shader, key)
        if found is None:
            return None
        texture, output = found
        asset = self._input_value(texture, "file")
        image = self._image(asset, f"material '{material_name}' {key}", f"{texture.GetPath()}.inputs:file",
                            signed=key == "normal")
        if image is None:
            return None
        wrap = tuple(_WRAP.get(str(self._input_value(texture, axis) or "useMetadata"), "repeat")
                     for axis in ("wrapS", "wrapT"))
        scale = self._input_value(texture, "scale")
        where = f"{self.path}: {texture.GetPath()}.inputs:scale"
        scale = np.ones(4) if scale is None else _numbers(scale, where, 4)
        if key in ("diffuseColor", "emissiveColor"):
            _colour(scale[:3], where)  # the colour factor: >= 0
        channels = {"r": "R", "g": "G", "b": "B", "a": "A"}
        if isinstance(image, _FloatImage):
            if output in channels:
                image = image.channel("rgba".index(output))
        elif output in channels:
            image = image.convert("RGBA").getchannel(channels[output])
        return image, {"wrap": wrap, "transform": None}, scale

    def _image(self, asset, what, key=None, signed=False):
        """A texture's PIL image from its asset path (a file, or a file inside a USDZ
        package); None with a warning when it is missing.  A path that is not a regular
        file (a directory, a device, a FIFO), a file larger than :data:`MAX_TEXTURE_BYTES` or
        an image of more than MAX_TEXTURE_PIXELS pixels is refused in one line naming the
        shader's ``key`` (``m.usda: /World/Looks/M/Tex.inputs:file: ...``)."""
        from PIL import Image

        if asset is None:
            return None
        resolved = getattr(asset, "resolvedPath", "") or ""
        authored = getattr(asset, "path", str(asset))
        try:
            if resolved.endswith("]") and "[" in resolved:
                package, inner = resolved[:-1].split("[", 1)
                zip_file = getattr(self.Sdf, "ZipFile", None) or self.Usd.ZipFile  # Usd's before 24.11
                data = zip_file.Open(package).GetFile(inner)
                if data is None:
                    raise OSError("not in the package")
                data = bytes(data)
            elif resolved:
                if os.path.lexists(resolved):
                    try:
                        check_file(resolved, "texture")
                    except MeshError as exc:
                        raise MeshError(f"{self.path}: {key or what}: {authored}: "
                                        f"{str(exc).removeprefix(resolved + ': ')}") from None
                    size = os.path.getsize(resolved)
                    if size > MAX_TEXTURE_BYTES:
                        raise MeshError(f"{self.path}: {key or what}: {authored}: a texture file of {size} bytes, "
                                        f"more than rtmesh reads ({MAX_TEXTURE_BYTES})")
                if os.path.splitext(resolved)[1].lower() in (".exr", ".hdr"):
                    return self._float_image(resolved, authored, key or what, signed)
                with open(resolved, "rb") as f:
                    data = f.read(MAX_TEXTURE_BYTES + 1)
            else:
                raise OSError("not found")
        except OSError as exc:
            log.warning("%s: %s: texture %s cannot be read (%s); not used", self.path, what, authored, exc)
            return None
        try:
            with image_size_guard(f"{self.path}: {key or what}: {authored}"):
                image = Image.open(io.BytesIO(data))
                check_texture_size(image, f"{self.path}: {key or what}: {authored}")
                image.load()
        except MeshError:
            raise
        except Exception as exc:  # PIL raises many types for corrupt images
            raise MeshError(f"{self.path}: {what}: texture {authored}: corrupt or unreadable "
                            f"({type(exc).__name__})") from None
        return image

    def _float_image(self, resolved, authored, where, signed=False):
        """An EXR or HDR texture's texels through OpenImageIO (as glTF's and scene files'
        textures are), its errors one line naming the shader's input."""
        try:
            texture = load_texture(resolved, srgb=False, signed=signed)
        except MeshError as exc:
            raise MeshError(f"{self.path}: {where}: {authored}: {str(exc).removeprefix(resolved + ': ')}") from None
        return _FloatImage(texture.pixels)


def _numbers(value, where, count):
    """``count`` numbers of a shader input (finite, at most 1e18 in magnitude), else a
    MeshError naming ``where``."""
    array = np.asarray(value) if not isinstance(value, str) else np.asarray([value])
    if array.dtype.kind not in "fiu" or array.size != count:
        raise MeshError(f"{where}: expected {count} numbers (got {value!r})")
    return usd_array(array.astype(np.float64).ravel(), where)


def _colour(value, where):
    """A colour input: 3 numbers, finite, >= 0 and at most 1e18 (the scene file's colours)."""
    colour = _numbers(value, where, 3)
    if (colour < 0).any():
        raise MeshError(f"{where}: a negative colour component ({float(colour.min()):g}); colours are >= 0")
    return colour


def _packed(rough, metal):
    """glTF's metallic-roughness texture (roughness in green, metalness in blue) of a
    preview surface's separate one-channel roughness and metallic textures."""
    from PIL import Image

    rough, metal = (None if t is None else (t[0].to_pil() if isinstance(t[0], _FloatImage) else t[0], *t[1:])
                    for t in (rough, metal))
    images = [t[0] for t in (rough, metal) if t is not None]
    size = max((image.size for image in images), key=lambda s: s[0] * s[1])
    zero = Image.new("L", size, 0)
    green = rough[0].convert("L").resize(size) if rough is not None else Image.new("L", size, 255)
    blue = metal[0].convert("L").resize(size) if metal is not None else Image.new("L", size, 255)
    options = (rough or metal)[1]
    return Image.merge("RGB", (zero, green, blue)), options
