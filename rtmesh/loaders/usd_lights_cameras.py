"""USD lights (``UsdLux``) and cameras (``UsdGeom.Camera``) to rtmesh's: distant,
sphere, rect and disk lights as directional, point, quad and disk lights (in the path
integrator's units, point-like ones divided by pi for Whitted's), a dome light as the
background, and a perspective or orthographic camera (see :mod:`rtmesh.loaders.usd_files`
for the mapping)."""

import math

import numpy as np

from rtmesh.core.errors import MeshError
from rtmesh.lights.area_lights import DiskLight, QuadLight
from rtmesh.lights.point_lights import DirectionalLight, PointLight
from rtmesh.loaders.usd_stage import usd_number
from rtmesh.scene.background import SolidBackground, read_environment
from rtmesh.scene.camera import Camera


class UsdLightCameraReader:
    """The USD reader's lights and cameras, each at its world transform in rtmesh's frame.

    A part of the reader (:class:`rtmesh.loaders.usd_files._Reader`): lights join its
    ``content.lights`` (point-like ones scaled by its ``point_units``), a dome light becomes
    ``content.background``; a camera's lens lengths are scaled by its ``meters``.
    """

    def _light(self, prim, world):
        UsdLux = self.UsdLux
        light = UsdLux.LightAPI(prim)

        from rtmesh.loaders.scene_keys import MAX_NUMBER, _colour, _float, _non_negative, _positive

        def get(attribute, default):
            value = attribute.Get(self.time) if attribute and attribute.HasValue() else None
            return default if value is None else value

        def where(attribute):
            return f"{self.path}: {prim.GetPath()}.{attribute.GetName()}"

        def number(attribute, default, reader=_non_negative):
            value = get(attribute, None)
            return default if value is None else usd_number(value, where(attribute), reader)

        # held to the scene file's limits for its lights, as glTF's are (gltf_nodes._light_at)
        colour_attr = light.GetColorAttr()
        colour = get(colour_attr, (1.0, 1.0, 1.0))
        values = np.asarray(colour) if not isinstance(colour, str) else np.asarray([colour])
        if values.dtype.kind not in "fiu" or values.size != 3:
            raise MeshError(f"{where(colour_attr)}: expected 3 numbers (got {colour!r})")
        try:
            colour = _colour([float(c) for c in values.ravel()])
        except TypeError as exc:
            raise MeshError(f"{where(colour_attr)}: {exc} (got {[float(c) for c in values.ravel()]})") from None
        intensity = number(light.GetIntensityAttr(), 1.0)
        exposure = number(light.GetExposureAttr(), 0.0, _float)
        try:
            gain = 2.0 ** exposure
        except OverflowError:
            gain = math.inf
        with np.errstate(all="ignore"):
            radiance = colour * intensity * gain if (colour * intensity > 0).any() else np.zeros(3)
        if not np.isfinite(radiance).all() or (radiance > MAX_NUMBER).any():
            raise MeshError(f"{where(light.GetIntensityAttr())}: color x intensity x 2^exposure "
                            f"{float(np.max(radiance)):g} is more than the largest intensity a scene file "
                            f"takes ({MAX_NUMBER:g})")
        normalize = bool(get(light.GetNormalizeAttr(), False))
        position = world[:3, 3]
        forward = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
        lengths = np.linalg.norm(world[:3, :3], axis=0)
        if not (np.isfinite(world).all() and (lengths > 0).all()):
            self._skip("lights with a zero scale or a non-finite transform (skipped)", prim)
            return
        if prim.IsA(UsdLux.DistantLight):
            self.content.lights.append(DirectionalLight(forward, radiance * self.point_units))
        elif prim.IsA(UsdLux.SphereLight):
            radius = number(UsdLux.SphereLight(prim).GetRadiusAttr(), 0.5) * float(lengths.mean())
            area = 4.0 * math.pi * radius ** 2
            scale = 1.0 / area if normalize and area > 0 else 1.0
            self.content.lights.append(PointLight(position, radiance * scale * math.pi * radius ** 2
                                                  * self.point_units))
        elif prim.IsA(UsdLux.RectLight):
            rect = UsdLux.RectLight(prim)
            width, height = (number(rect.GetWidthAttr(), 1.0, _positive),
                             number(rect.GetHeightAttr(), 1.0, _positive))
            edge1 = world[:3, :3] @ np.array([0.0, height, 0.0])
            edge2 = world[:3, :3] @ np.array([width, 0.0, 0.0])
            area = float(np.linalg.norm(np.cross(edge1, edge2)))
            self.content.lights.append(QuadLight(position, edge1, edge2,
                                                 radiance / area if normalize and area > 0 else radiance))
        elif prim.IsA(UsdLux.DiskLight):
            radius = number(UsdLux.DiskLight(prim).GetRadiusAttr(), 0.5, _positive) * float(lengths[:2].mean())
            area = math.pi * radius ** 2
            self.content.lights.append(DiskLight(position, forward, radius,
                                                 radiance / area if normalize and area > 0 else radiance))
        elif prim.IsA(UsdLux.DomeLight):
            self.content.background = self._dome(prim, radiance)
        else:
            self._skip("lights of types rtmesh does not have (skipped)", prim)

    def _dome(self, prim, radiance):
        asset = self.UsdLux.DomeLight(prim).GetTextureFileAttr().Get(self.time)
        resolved = getattr(asset, "resolvedPath", "") if asset else ""
        if resolved and "[" not in resolved:
            background = read_environment(resolved, 0.0, float(np.mean(radiance)))
        else:
            if asset and getattr(asset, "path", ""):
                self._skip("dome textures that cannot be read (a solid colour used)", prim)
            background = SolidBackground(radiance)
        background.lighting = True
        return background

    def _camera(self, prim, world):
        UsdGeom = self.UsdGeom
        camera = UsdGeom.Camera(prim)

        from rtmesh.loaders.scene_keys import _non_negative, _positive

        def get(attribute, default, reader=_positive):
            value = attribute.Get(self.time) if attribute else None
            if value is None:
                return default
            return usd_number(value, f"{self.path}: {prim.GetPath()}.{attribute.GetName()}", reader)

        position = world[:3, 3]
        forward = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
        up = world[:3, :3] @ np.array([0.0, 1.0, 0.0])
        if not (np.isfinite(world).all() and np.linalg.norm(forward) > 0 and np.linalg.norm(up) > 0):
            self._skip("cameras with a zero scale or a non-finite transform (skipped)", prim)
            return None
        forward = forward / np.linalg.norm(forward)
        focal = get(camera.GetFocalLengthAttr(), 50.0)
        vertical = get(camera.GetVerticalApertureAttr(), 15.2908)
        # apertures and focal length are in tenths of a scene unit
        tenth = 0.1 * self.meters
        if camera.GetProjectionAttr().Get(self.time) == UsdGeom.Tokens.orthographic:
            height = vertical * tenth * float(np.linalg.norm(up))
            return Camera(position, position + forward, up, projection="orthographic", ortho_height=height)
        fov = math.degrees(2.0 * math.atan(0.5 * vertical / focal))
        if not 0.0 < fov < 180.0:  # a focal length tiny beside the aperture: rounds to 180
            raise MeshError(f"{self.path}: {prim.GetPath()}.focalLength: {focal:g} with a vertical aperture of "
                            f"{vertical:g} is a field of view of {fov:g} degrees (it must be less than 180)")
        f_stop = get(camera.GetFStopAttr(), 0.0, _non_negative)
        focus = get(camera.GetFocusDistanceAttr(), 0.0, _non_negative)
        aperture = focal * tenth / f_stop if f_stop > 0 and focus > 0 else 0.0
        return Camera(position, position + forward, up, fov=fov, aperture=aperture,
                      focus_distance=focus * self.meters if aperture > 0 else None)
