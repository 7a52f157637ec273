"""A stand-in for openpi's ``serve_policy`` with a DROID policy, for tests.

Written independently of :mod:`molmo_lerobot.serving.server` (only the codec is shared) so
that our client is tested against openpi's behaviour, not against our own server: metadata
frame on connect, no reset endpoint, strict request -> response, the traceback as a text
frame then close 1011 on any error, ``/healthz``. It checks every DROID key, dtype and
shape, and answers ``actions`` of shape (H, 8).
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import traceback
from collections.abc import Iterator
from http import HTTPStatus

import msgpack
import numpy as np
from websockets.asyncio.server import serve
from websockets.exceptions import ConnectionClosed
from websockets.frames import CloseCode

from molmo_lerobot.protocol.codec import packb, unpackb

DROID_IMAGES = ("observation/exterior_image_1_left", "observation/wrist_image_left")


def check_droid(obs: dict) -> None:
    for key in DROID_IMAGES:
        img = obs[key]
        assert isinstance(img, np.ndarray) and img.dtype == np.uint8 and img.shape == (224, 224, 3), (key, img)
    joints, grip = obs["observation/joint_position"], obs["observation/gripper_position"]
    assert joints.shape == (7,) and np.isfinite(joints).all(), joints
    assert grip.shape == (1,) and 0.0 <= float(grip[0]) <= 1.0, grip
    assert isinstance(obs["prompt"], str) and obs["prompt"], obs["prompt"]
    extra = set(obs) - {*DROID_IMAGES, "observation/joint_position", "observation/gripper_position", "prompt"}
    assert not extra, f"unexpected keys {extra}"


class FakeDroidServer:
    """``mode``: ok | nan | bad_shape | string_dtype | silent (never answers a request) | silent_metadata."""

    #: checks a request (raises on a misfit); another client convention's server overrides it and ``answer``
    check = staticmethod(check_droid)

    def __init__(self, horizon: int = 10, mode: str = "ok", velocity: float = 0.1, port: int = 0) -> None:
        self.horizon, self.mode, self.velocity = horizon, mode, velocity
        self.port = port
        self.connections = 0
        self.requests = 0
        self.errors: list[str] = []

    async def _handler(self, ws) -> None:
        self.connections += 1
        try:
            if self.mode == "silent_metadata":
                await ws.wait_closed()
                return
            await ws.send(packb({"policy": "fake-droid"}))
            while True:
                obs = unpackb(await ws.recv())
                self.requests += 1
                if self.mode == "silent":
                    await ws.wait_closed()
                    return
                try:
                    self.check(obs)
                except Exception:
                    self.errors.append(traceback.format_exc())
                    raise
                actions = np.array(self.answer(obs), dtype=np.float32)
                if self.mode == "nan":
                    actions[1, 3] = np.nan
                elif self.mode == "bad_shape":
                    actions = actions[:, :5]
                if self.mode == "string_dtype":  # a hostile server: numpy 2 StringDType bytes hold pointers
                    await ws.send(msgpack.packb({"actions": {b"__ndarray__": True, b"data": b"\x41" * 16,
                                                             b"dtype": "T", b"shape": [1]}}, use_bin_type=True))
                    continue
                await ws.send(packb({"actions": actions, "server_timing": {"infer_ms": 0.1}}))
        except ConnectionClosed:
            pass
        except Exception:
            with contextlib.suppress(ConnectionClosed):
                await ws.send(traceback.format_exc())
                await ws.close(CloseCode.INTERNAL_ERROR, "Internal server error. Traceback included in previous frame.")

    def answer(self, obs: dict) -> np.ndarray:
        """The (H, 8) actions for a checked request: ``velocity`` on every joint, the gripper 0 … 1."""
        actions = np.zeros((self.horizon, 8), dtype=np.float32)
        actions[:, :7] = self.velocity
        actions[:, 7] = np.linspace(0, 1, self.horizon)
        return actions

    @staticmethod
    def _health(connection, request):
        return connection.respond(HTTPStatus.OK, "OK\n") if request.path == "/healthz" else None

    @contextlib.contextmanager
    def running(self) -> Iterator[FakeDroidServer]:
        loop = asyncio.new_event_loop()
        started, stop = threading.Event(), asyncio.Event()

        async def main() -> None:
            async with serve(self._handler, "127.0.0.1", self.port, compression=None, max_size=None,
                             ping_interval=None, process_request=self._health) as server:
                self.port = server.sockets[0].getsockname()[1]
                started.set()
                await stop.wait()
                server.close(close_connections=True)

        thread = threading.Thread(target=lambda: loop.run_until_complete(main()), daemon=True)
        thread.start()
        assert started.wait(10), "fake DROID server did not start"
        try:
            yield self
        finally:
            loop.call_soon_threadsafe(stop.set)
            thread.join(10)
            loop.close()
