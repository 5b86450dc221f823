"""Behaviour that more than one layer needs, on the ground floor beside `records`: loading plug-ins
(`plugins`), numba kernels that a stop interrupts (`compiled`), the folder numba caches them in
(`numba_cache`), the ego's neighbours in a world snapshot (`neighbours`), and UN R157's minimum
following distance with the gap every start keeps on top of it (`r157`). It imports only
`records`; `perception`, `planner`, `controllers` and `stack` may import it."""

from common import numba_cache  # noqa: F401  numba's cache folder is set before anything compiles
