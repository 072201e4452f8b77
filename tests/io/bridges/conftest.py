"""A real MQTT broker for the bridge tests: Mosquitto from the distribution, on a free loopback
port, with persistence so a subscriber's session survives a broker restart."""

from __future__ import annotations

import os
import pwd
import shutil
import signal
import socket
import subprocess
import time

import pytest


def _mosquitto():
    for path in (shutil.which("mosquitto"), "/usr/sbin/mosquitto"):
        if path and os.access(path, os.X_OK):
            return path
    return None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Broker:
    def __init__(self, exe, workdir):
        self.exe = exe
        self.port = free_port()
        self.workdir = workdir
        self.conf = workdir / "mosquitto.conf"
        # as root, mosquitto would switch to its own user, who may not read the test's directory
        user = pwd.getpwuid(os.getuid()).pw_name
        self.conf.write_text(f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence true\n"
                             f"persistence_location {workdir}/\nautosave_interval 1\nuser {user}\n")
        self.proc = None
        self.log = open(workdir / "mosquitto.log", "ab")

    def start(self, timeout=20):
        self.proc = subprocess.Popen([self.exe, "-c", str(self.conf)], stdout=self.log, stderr=self.log)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:          # ready when it accepts a connection
            if self.proc.poll() is not None:
                raise RuntimeError(f"mosquitto exited {self.proc.returncode}: "
                                   f"{(self.workdir / 'mosquitto.log').read_text()}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.5):
                    return self
            except OSError:
                time.sleep(0.02)
        raise RuntimeError("mosquitto did not start")

    def stop(self):
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self.proc = None

    @property
    def url(self):
        return f"mqtt://127.0.0.1:{self.port}"


@pytest.fixture
def broker(tmp_path):
    exe = _mosquitto()
    if exe is None:
        pytest.skip("mosquitto is not installed (apt-get install mosquitto)")
    work = tmp_path / "broker"
    work.mkdir()
    b = Broker(exe, work).start()
    yield b
    b.stop()
    b.log.close()
