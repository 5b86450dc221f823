"""The paper's network sizes by name (hidden layer widths); no torch import, so configs load fast."""

NET_ARCHS: dict[str, list[int]] = {
    "shallow": [32],
    "medium": [32, 64, 32],
    "deep": [64, 128, 128, 64],
    "16": [16],
    "16x16": [16, 16],
}


def net_arch(name: str) -> list[int]:
    if name not in NET_ARCHS:
        raise ValueError(f"unknown network {name!r}; available: {', '.join(NET_ARCHS)}")
    return NET_ARCHS[name]
