"""Fixtures of the protocol tests (helpers in proto_helpers.py)."""

from __future__ import annotations

import subprocess
from typing import Any

import pytest
from proto_helpers import LIB_PATH, REPO_ROOT, CppCodec, load_vectors


@pytest.fixture(scope="session")
def cpp() -> CppCodec:
    # make knows whether the library is stale; quick when it is not.
    result = subprocess.run(
        ["make", "-s", str(LIB_PATH.relative_to(REPO_ROOT))],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
    )
    if result.returncode != 0:
        pytest.fail(f"building {LIB_PATH.name} failed:\n{result.stdout}\n{result.stderr}")
    return CppCodec(LIB_PATH)


@pytest.fixture(scope="session")
def message_vectors() -> dict[str, Any]:
    return load_vectors("messages.json")


@pytest.fixture(scope="session")
def stream_vectors() -> dict[str, Any]:
    return load_vectors("streams.json")


@pytest.fixture(scope="session")
def handmade_vectors() -> dict[str, Any]:
    return load_vectors("handmade.json")
