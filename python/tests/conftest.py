"""Datasets the suite reads: tests/python_pkg.rs (run by `cargo test`) makes them and names
them in NRW_TEST_DEMO, NRW_TEST_SCEAUX and NRW_TEST_RUST_DRAWS."""

import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(__file__))


def _given(var):
    value = os.environ.get(var)
    if not value:
        pytest.skip(f"{var} is not set: `cargo test` runs this suite on datasets it makes (tests/python_pkg.rs)")
    return value


@pytest.fixture(scope="session")
def demo():
    """The embedded demo's dataset (semantics, normals, style descriptors, triplets)."""
    return _given("NRW_TEST_DEMO")


@pytest.fixture(scope="session")
def rust_draws():
    """The Rust Loader's crops and the Rust triplet sampler's draws on the demo."""
    return _given("NRW_TEST_RUST_DRAWS")


@pytest.fixture(scope="session", params=["demo", "sceaux_castle"])
def dataset(request):
    """Each dataset in turn: the demo, then sceaux_castle (a real scene)."""
    return _given({"demo": "NRW_TEST_DEMO", "sceaux_castle": "NRW_TEST_SCEAUX"}[request.param])
