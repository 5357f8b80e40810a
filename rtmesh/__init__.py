"""rtmesh: a CPU ray tracer for triangle-mesh scenes.

trimesh loads the meshes, Embree (through embreex) traces the rays, NumPy shades them and
OpenImageIO writes the images.

>>> import rtmesh
>>> result = rtmesh.render("assets/showcase.toml", width=320, height=240)  # doctest: +SKIP
>>> result.image.shape, result.stats.rays["camera"]  # doctest: +SKIP
((240, 320, 3), 307200)
"""

__version__ = "0.1.0"

from rtmesh.api import load_scene, render  # noqa: E402
from rtmesh.batch.runner import batch_convert  # noqa: E402
from rtmesh.core.errors import MeshError, OutputError, RtmeshError, SceneError  # noqa: E402
from rtmesh.io.images import read_image, write_image  # noqa: E402
from rtmesh.rendering.settings import RenderSettings  # noqa: E402

__all__ = ["load_scene", "render", "batch_convert", "write_image", "read_image", "RenderSettings",
           "RtmeshError", "SceneError", "MeshError", "OutputError", "__version__"]
