"""Many closed loops stepped together as [worlds, vehicles] arrays: the loop, its compiled kernels
and its episode metrics, each world the `vector` backend's loop alone, bit for bit."""
