"""The width of Embree's native packet queries on this CPU (see
:mod:`rtmesh.geometry.embree_packets`, whose packets are laid out in groups of it).

A module of its own, importing nothing of rtmesh: the kernels' disk-cache stamp
(:func:`rtmesh.core.compiled.package_stamp`) includes the width, and is computed while the
kernel modules are being imported.
"""


def native_group(features=None):
    """The widest packet Embree traces natively on this CPU: 16 lanes with AVX-512 (Embree's
    AVX-512 code needs the F, CD, DQ, BW and VL parts, as Skylake-X has them), 8 with AVX or
    AVX2, 4 otherwise (SSE).  Embree reports the same through ``rtcGetDeviceProperty``
    (``RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED`` ...; the tests compare the two); this
    reads the CPU's features through LLVM, which numba imports anyway, so that the layout is
    known before the library is opened.

    Parameters
    ----------
    features : mapping of str to bool, optional
        CPU feature flags as LLVM names them (default: this machine's).

    Returns
    -------
    int
        4, 8 or 16.
    """
    if features is None:
        from llvmlite import binding

        features = binding.get_host_cpu_features()
    if all(features.get(name, False) for name in ("avx512f", "avx512cd", "avx512dq", "avx512bw", "avx512vl")):
        return 16
    return 8 if features.get("avx", False) else 4
