"""Fixtures of the command tests."""

from __future__ import annotations

import os
import select

import pytest


@pytest.fixture
def pty_port():
    """A pty whose other end nobody answers: (slave path, function returning what was written)."""
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)

    def written():
        data = b""
        while select.select([master], [], [], 0.05)[0]:
            data += os.read(master, 4096)
        return data

    yield os.ttyname(slave), written
    os.close(master)
    os.close(slave)
