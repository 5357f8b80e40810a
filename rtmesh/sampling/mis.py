"""Multiple importance sampling weights (Veach 1997, ch. 9)."""

import math

from rtmesh.core.compiled import row


@row
def power_heuristic(pdf_f, pdf_g):
    """Weight of a sample drawn by strategy f, against strategy g (one sample each):
    ``pdf_f^2 / (pdf_f^2 + pdf_g^2)``; 1 where g cannot draw it, and 1 for an infinite
    ``pdf_f`` (a delta lobe or light, which the other strategy never draws)."""
    if math.isinf(pdf_f):
        return 1.0
    if not pdf_g > 0.0:
        return 1.0
    f2 = pdf_f * pdf_f
    return f2 / (f2 + pdf_g * pdf_g)
