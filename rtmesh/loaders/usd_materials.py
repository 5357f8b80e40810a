"""USD materials to rtmesh's: ``UsdPreviewSurface`` (with ``UsdUVTexture`` textures read
through ``UsdPrimvarReader_float2``) mapped onto the glTF metallic-roughness model that
glTF files load as (:func:`rtmesh.loaders.gltf_materials.gltf_material`), and the
``displayColor`` material of a prim without one; textures read from files or from inside a
USDZ package."""

import io
import logging

import numpy as np
import trimesh

from rtmesh.core.errors import MeshError
from rtmesh.loaders.gltf_materials import OPTIONS_KEY, gltf_material

log = logging.getLogger(__name__)

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

        def number(key, default):
            value = self._input_value(shader, key)
            return default if value is None else float(value)

        def colour(key, default):
            value = self._input_value(shader, key)
            return list(default) if value is None else [float(c) for c in value]

        if number("useSpecularWorkflow", 0.0):
            self._skip("materials in the specular workflow (read as metallic-roughness)", material.GetPrim())
        opacity = number("opacity", 1.0)
        threshold = number("opacityThreshold", 0.0)
        options, images = {}, {}
        base = colour("diffuseColor", (0.18, 0.18, 0.18))
        emissive = colour("emissiveColor", (0.0, 0.0, 0.0))
        metallic, roughness = number("metallic", 0.0), number("roughness", 0.5)

        diffuse = self._texture(shader, "diffuseColor", name)
        if diffuse is not None:
            images["baseColorTexture"], options["baseColorTexture"], scale = diffuse
            base = list(scale[:3])
        emission = self._texture(shader, "emissiveColor", name)
        if emission is not None:
            images["emissiveTexture"], options["emissiveTexture"], scale = emission
            emissive = list(scale[:3])
        normal = self._texture(shader, "normal", name)
        if normal is not None:
            images["normalTexture"], options["normalTexture"], _ = normal
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
        return gltf_material(pbr, json_material, name, self.path)

    def _texture(self, shader, key, material_name):
        """(PIL image of the channels the input reads, texture options, scale (4,)) of a
        UsdUVTexture connected to ``key``, or None."""
        found = self._texture_source(shader, key)
        if found is None:
            return None
        texture, output = found
        asset = self._input_value(texture, "file")
        image = self._image(asset, f"material '{material_name}' {key}")
        if image is None:
            return None
        wrap = tuple(_WRAP.get(str(self._input_value(texture, axis) or "useMetadata"), "repeat")
                     for axis in ("wrapS", "wrapT"))
        scale = self._input_value(texture, "scale")
        scale = np.ones(4) if scale is None else np.asarray(scale, dtype=np.float64)
        channels = {"r": "R", "g": "G", "b": "B", "a": "A"}
        if output in channels:
            image = image.convert("RGBA").getchannel(channels[output])
        return image, {"wrap": wrap, "transform": None}, scale

    def _image(self, asset, what):
        """A texture's PIL image from its asset path (a file, or a file inside a USDZ
        package); None with a warning when it is missing."""
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
                with open(resolved, "rb") as f:
                    data = f.read()
            else:
                raise OSError("not found")
        except OSError as exc:
            log.warning("%s: %s: texture %s cannot be read (%s); not used", self.path, what, authored, exc)
            return None
        try:
            image = Image.open(io.BytesIO(data))
            image.load()
        except Exception as exc:  # PIL raises many types for corrupt images
            raise MeshError(f"{self.path}: {what}: texture {authored}: corrupt or unreadable "
                            f"({type(exc).__name__})") from None
        return image


def _packed(rough, metal):
    """glTF's metallic-roughness texture (roughness in green, metalness in blue) of a
    preview surface's separate one-channel roughness and metallic textures."""
    from PIL import Image

    images = [t[0] for t in (rough, metal) if t is not None]
    size = max((image.size for image in images), key=lambda s: s[0] * s[1])
    zero = Image.new("L", size, 0)
    green = rough[0].convert("L").resize(size) if rough is not None else Image.new("L", size, 255)
    blue = metal[0].convert("L").resize(size) if metal is not None else Image.new("L", size, 255)
    options = (rough or metal)[1]
    return Image.merge("RGB", (zero, green, blue)), options
