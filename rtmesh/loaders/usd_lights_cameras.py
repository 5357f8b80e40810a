"""USD lights (``UsdLux``) and cameras (``UsdGeom.Camera``) to rtmesh's: distant,
sphere, rect and disk lights as directional, point, quad and disk lights (in the path
integrator's units, point-like ones divided by pi for Whitted's), a dome light as the
background, and a perspective or orthographic camera (see :mod:`rtmesh.loaders.usd_files`
for the mapping)."""

import math

import numpy as np

from rtmesh.lights.area_lights import DiskLight, QuadLight
from rtmesh.lights.point_lights import DirectionalLight, PointLight
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

        def get(attribute, default):
            value = attribute.Get(self.time) if attribute and attribute.HasValue() else None
            return default if value is None else value

        radiance = (np.asarray(get(light.GetColorAttr(), (1.0, 1.0, 1.0)), dtype=np.float64)
                    * float(get(light.GetIntensityAttr(), 1.0)) * 2.0 ** float(get(light.GetExposureAttr(), 0.0)))
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
            radius = float(get(UsdLux.SphereLight(prim).GetRadiusAttr(), 0.5)) * float(lengths.mean())
            area = 4.0 * math.pi * radius ** 2
            scale = 1.0 / area if normalize and area > 0 else 1.0
            self.content.lights.append(PointLight(position, radiance * scale * math.pi * radius ** 2
                                                  * self.point_units))
        elif prim.IsA(UsdLux.RectLight):
            rect = UsdLux.RectLight(prim)
            width, height = float(get(rect.GetWidthAttr(), 1.0)), float(get(rect.GetHeightAttr(), 1.0))
            edge1 = world[:3, :3] @ np.array([0.0, height, 0.0])
            edge2 = world[:3, :3] @ np.array([width, 0.0, 0.0])
            area = float(np.linalg.norm(np.cross(edge1, edge2)))
            self.content.lights.append(QuadLight(position, edge1, edge2,
                                                 radiance / area if normalize and area > 0 else radiance))
        elif prim.IsA(UsdLux.DiskLight):
            radius = float(get(UsdLux.DiskLight(prim).GetRadiusAttr(), 0.5)) * float(lengths[:2].mean())
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

        def get(attribute, default):
            value = attribute.Get(self.time) if attribute else None
            return default if value is None else float(value)

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
        f_stop, focus = get(camera.GetFStopAttr(), 0.0), get(camera.GetFocusDistanceAttr(), 0.0)
        aperture = focal * tenth / f_stop if f_stop > 0 and focus > 0 else 0.0
        return Camera(position, position + forward, up, fov=fov, aperture=aperture,
                      focus_distance=focus * self.meters if aperture > 0 else None)
