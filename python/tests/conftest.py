"""Fixtures: a real hub process (the `iwsim` binary named by $IWSIM_BIN) in a session of its own."""

from __future__ import annotations

import os
import pathlib
import subprocess
import uuid

import pytest


def iwsim_bin() -> str:
    path = os.environ.get("IWSIM_BIN")
    if not path:
        pytest.fail("IWSIM_BIN must name the iwsim binary (the Rust e2e test `python` sets it)")
    return path


class Hub:
    """A hub process; stopped (SIGTERM, then waited for) when the test ends."""

    def __init__(self, *args: str) -> None:
        self.session = f"py-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        self.proc = subprocess.Popen(
            [iwsim_bin(), "hub", "--session", self.session, *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )

    def stop(self) -> str:
        if self.proc.poll() is None:
            self.proc.terminate()
        out, err = self.proc.communicate(timeout=20)
        return out + err


@pytest.fixture
def hub_factory():
    hubs: list[Hub] = []

    def start(*args: str) -> Hub:
        h = Hub(*args)
        hubs.append(h)
        return h

    yield start
    for h in hubs:
        h.stop()
    # Nothing of any session of this test is left in shared memory.
    left = [p.name for p in pathlib.Path("/dev/shm").glob("iwsim_*") if any(h.session in p.name for h in hubs)]
    assert not left, f"left in /dev/shm: {left}"
