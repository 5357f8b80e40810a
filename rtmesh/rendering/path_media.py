"""The path and photon kernels' nested media, as compiled rows: each lane carries a stack of
the transmissive materials it is inside (innermost first, -1 padded); an interface's index
ratio is between the media on its two sides; a refraction pushes or pops the stack, and
faces that touch (glass in water: the same vertices, opposite windings) are crossed
together, as the Whitted integrator's :mod:`rtmesh.rendering.media` does.

The rows are inlined into the kernels (``inline_row``: see
:mod:`rtmesh.rendering.path_surfaces`).
"""

from rtmesh.core.compiled import inline_row
from rtmesh.materials import lobes, models


@inline_row
def twin_material(surface, prim):
    """The material of the transmissive face that touches face ``prim`` from the other side
    (the same three vertex positions, the opposite winding: glass touching water), -1 for
    none (:func:`rtmesh.rendering.media.coincident_faces`)."""
    twins = surface[16]
    return twins[prim] if len(twins) else -1


@inline_row
def interface_ratio(stack, lane, mat, entering, ior, twin):
    """The index ratio of a transmissive material's interface between the media on its two
    sides: its index over that of the medium the ray comes from (entering) or goes into
    (leaving); ``stack[lane]`` holds the media the ray is inside, innermost first, -1 padded.
    A face touching another medium's (``twin`` its material, -1 none) has that medium on
    its other side, whichever of the two faces the ray met (as the Whitted integrator's
    twins, :mod:`rtmesh.rendering.media`): one medium to the other directly, and an
    interface between two bodies of one material is invisible (ratio 1)."""
    if twin >= 0:
        return ior[mat] / ior[twin]
    top = stack[lane, 0]
    if entering:
        other = top
    else:
        other = stack[lane, 1] if top == mat else top
    return ior[mat] / (ior[other] if other >= 0 else 1.0)


@inline_row
def crossing_scale(slots, tag, bsdf_params, bsdf_row, loz, flags):
    """``eta'^2`` of a sampled refraction (``flags`` with ``lobes.TRANSMISSION``, a model
    with an ``ior`` slot; ``loz`` the outgoing direction's local z, positive outside), the
    inverse of the radiance scaling ``1 / eta'^2`` the seam applies to it for camera paths;
    1 for any other sample."""
    if flags & lobes.TRANSMISSION:
        slot = slots[tag, models.IOR_SLOT]
        if slot >= 0:
            eta = bsdf_params[bsdf_row, slot]
            etap = eta if loz > 0.0 else 1.0 / eta
            return etap * etap
    return 1.0


@inline_row
def cross_interface(stack, lane, mat, into, twin):
    """Update a lane's media stack as its ray refracts through material ``mat``: into its
    interior (push) or out of it (pop, when it is the innermost); through touching faces
    (``twin`` the other face's material, :func:`twin_material`) out of the one medium and
    into the other, leaving first.  Returns the innermost medium after (-1: none)."""
    if twin >= 0 and into:
        _cross(stack, lane, twin, False)
    _cross(stack, lane, mat, into)
    if twin >= 0 and not into:
        _cross(stack, lane, twin, True)
    return stack[lane, 0]


@inline_row
def _cross(stack, lane, mat, into):
    """One crossing of :func:`cross_interface`."""
    media = stack.shape[1]
    if into:
        for k in range(media - 1, 0, -1):
            stack[lane, k] = stack[lane, k - 1]
        stack[lane, 0] = mat
    elif stack[lane, 0] == mat:
        for k in range(media - 1):
            stack[lane, k] = stack[lane, k + 1]
        stack[lane, media - 1] = -1
