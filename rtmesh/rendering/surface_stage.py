"""The surface stage: shading records of the rays that hit (points, normals facing the
incoming ray, materials, texture tints), with motion blur formed on the rest pose of the
object hit and moved to the ray's time, and hits on placed meshes carried to the world by
their placement (:mod:`rtmesh.scene.instances`).
"""

import numpy as np

from rtmesh.core.compiled import by_component
from rtmesh.core.rays import NO_VECTORS, take_rows
from rtmesh.rendering.chunk_state import Stage, SurfaceRecords
from rtmesh.shading.surfaces import face_viewer, placed_surface_records, surface_records

_NO_NORMALS = np.zeros((0, 3))


class SurfaceStage(Stage):
    """Surface records for one integrator's scene (its face tables, textures, motion)."""

    def records(self, rays, hits, rows, sample_time=None):
        """Hit points, normals facing the incoming ray, and material ids of the hit ``rows``
        (see :func:`rtmesh.shading.surfaces.surface_records`).

        With motion blur, points and normals are formed on the rest pose of the object hit
        and moved to the ray's time at the end (see :mod:`rtmesh.geometry.motion`).
        """
        it = self.it
        srf = SurfaceRecords()
        srf.sample = take_rows(rays.sample, rows)
        srf.time = None if sample_time is None else sample_time[srf.sample]
        srf.d = take_rows(rays.directions, rows)
        srf.prim = take_rows(hits.prim, rows)
        srf.pdf = None if rays.pdf is None else take_rows(rays.pdf, rows)
        srf.origin = None if rays.pdf is None else take_rows(rays.origins, rows)
        srf.physical = None
        view = NO_VECTORS
        if srf.time is not None:
            view = it.motion.directions_to_rest(srf.prim.astype(np.intp), srf.time, srf.d)
        normal_maps = it.plan.normal_maps
        # the shading-normal terminator fix (see face_viewer) runs in the kernel unless
        # normal maps, applied below, change the normals after it
        fix_terminator = it.plan.smooth_normals and not normal_maps
        hit_rows = np.arange(len(hits)) if rows is None else rows
        if hits.instance is not None:
            # placed meshes: the hits on a placement carried to the world, as their copies read
            _, to_world, normal_to_world = it.instances.world_rows()
            scene = it.scene
            srf.p, srf.ng, srf.ns, srf.front, srf.mat = placed_surface_records(
                hits.prim, hits.u, hits.v, hits.instance, hit_rows, by_component(rays.directions),
                it.tables.faces, it.tables.vertex_normals, it.tables.smooth, it.tables.material_id, fix_terminator,
                to_world, normal_to_world, scene.faces,
                _NO_NORMALS if scene.vertex_normals is None else scene.vertex_normals)
        else:
            srf.p, srf.ng, srf.ns, srf.front, srf.mat = surface_records(
                hits.prim, hits.u, hits.v, hit_rows, by_component(rays.directions), view, it.tables.faces,
                it.tables.vertex_normals, it.tables.smooth, it.tables.material_id, fix_terminator)
        srf.tints = None
        if it.plan.textures:
            u, v = take_rows(hits.u, rows), take_rows(hits.v, rows)
            srf.tints = it.textures.tints(srf.prim, u, v, srf.mat)
            if normal_maps:
                flip = np.where(srf.front, 1.0, -1.0)
                tangents = None
                if hits.instance is not None:
                    # a placed face's UV tangents carried to the world, as the copies' read
                    tangents = it.instances.world_tangents(it.textures.tangents[srf.prim],
                                                           take_rows(hits.instance, rows))
                srf.ns = it.textures.normal_mapped(srf.ns, srf.prim, u, v, srf.mat, flip, tangents)
                # in the rest frame, like ns and ng
                srf.ns = face_viewer(srf.ns, srf.ng, srf.d if srf.time is None else view)
        if srf.time is not None:
            srf.p, srf.ng, srf.ns = it.motion.surfaces_to_world(srf.prim, srf.time, srf.p, srf.ng,
                                                                  srf.ns)
        return srf
