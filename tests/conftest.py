import pytest

from stack.core.config import build_config


@pytest.fixture
def tiny_config():
    """A short, sparse run: 8 s episodes with 15 vehicles."""
    return build_config(
        {"episodes": 1, "highway": {"vehicles_count": 15, "duration": 8}},
        "tiny",
    )
