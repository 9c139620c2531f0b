"""Where the tests find the flat sample and the `voxpan` command line.

The flat sample: $VOXPAN_FLAT_DIR, else ../shared/data/flat beside the checkout (as the Rust
tests). Without it the data tests fail, unless VOXPAN_ALLOW_MISSING_DATA=1 (then they skip).
The command line: $VOXPAN_BIN, else target/debug/voxpan or target/release/voxpan of the
checkout (`cargo build -p voxpan`). Open3D (the interop test; setup.sh installs open3d-cpu): a
failed import fails that test, unless VOXPAN_ALLOW_MISSING_DATA=1 (then it skips).
"""

import os
import pathlib

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]


def missing(message: str):
    """Fails the test, or skips it saying why where missing inputs are allowed."""
    if os.environ.get("VOXPAN_ALLOW_MISSING_DATA") == "1":
        pytest.skip(f"SKIPPED {message}")
    pytest.fail(message)


@pytest.fixture(scope="session")
def flat_dir() -> pathlib.Path:
    env = os.environ.get("VOXPAN_FLAT_DIR")
    path = pathlib.Path(env) if env else REPO.parent / "shared" / "data" / "flat"
    if not (path / "run1").is_dir():
        missing(f"the flat sample is missing ({path}; set VOXPAN_FLAT_DIR)")
    return path


@pytest.fixture(scope="session")
def open3d():
    try:
        import open3d as o3d
    except (ImportError, OSError) as e:
        # The usual cause on a bare Debian: libusb-1.0-0 (setup.sh installs it as root).
        missing(f"open3d cannot be imported ({e}; bindings/python/setup.sh installs it)")
    return o3d


@pytest.fixture(scope="session")
def voxpan_bin() -> pathlib.Path:
    env = os.environ.get("VOXPAN_BIN")
    candidates = [pathlib.Path(env)] if env else [
        REPO / "target" / "debug" / "voxpan",
        REPO / "target" / "release" / "voxpan",
    ]
    for c in candidates:
        if c.is_file():
            return c
    pytest.fail(
        "no voxpan binary: run `cargo build -p voxpan` or set VOXPAN_BIN "
        f"(looked at {', '.join(map(str, candidates))})"
    )
