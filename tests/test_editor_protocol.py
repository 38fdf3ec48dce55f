"""The editor's upload checks through the real websocket protocol (no browser needed).

A client speaking viser's wire format (msgpack messages over a websocket) uploads
sessions exactly as the page's upload button does: a ``FileTransferStartUpload`` message,
then ``FileTransferPart`` messages. Bad sessions must come back as a notification in the
page and change nothing; uploads over the cap must be dropped while they arrive.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import pytest

msgpack = pytest.importorskip("msgpack", reason="msgpack (a viser dependency) is needed")
ws_client = pytest.importorskip("websockets.sync.client", reason="websockets is needed")
zstandard = pytest.importorskip("zstandard", reason="zstandard (a viser dependency) is needed")

import viser  # noqa: E402

from arapkit.cli.edit import build_state  # noqa: E402
from arapkit.editor.app import EditorApp  # noqa: E402
from tests.test_editor_browser import free_port, wait_for  # noqa: E402


class Client:
    """A minimal viser client: sends messages, collects every frame received."""

    def __init__(self, port: int) -> None:
        self.ws = ws_client.connect(f"ws://127.0.0.1:{port}", max_size=None,
                                    subprotocols=[f"viser-v{viser.__version__}"])
        self.frames: list[bytes] = []
        # viser counts a client as connected once it reports its camera, as the page does
        self.send(type="ViewerCameraMessage", wxyz=[1.0, 0, 0, 0], position=[0.0, 0, -10],
                  fov=1.0, near=0.01, far=1000.0, image_height=480, image_width=640,
                  look_at=[0.0, 0, 0], up_direction=[0.0, -1, 0])

    def send(self, **msg) -> None:
        self.ws.send(msgpack.packb(msg, use_bin_type=True))

    def upload(self, uuid: str, transfer: str, name: str, parts: list[bytes],
               declared: int | None = None) -> None:
        size = sum(map(len, parts)) if declared is None else declared
        self.send(type="FileTransferStartUpload", source_component_uuid=uuid,
                  transfer_uuid=transfer, filename=name, mime_type="application/json",
                  part_count=len(parts) if declared is None else max(len(parts), 2),
                  size_bytes=size)
        for i, p in enumerate(parts):
            self.send(type="FileTransferPart", source_component_uuid=uuid,
                      transfer_uuid=transfer, part_index=i, content=p)

    @staticmethod
    def _payload(frame: bytes) -> bytes:
        """The msgpack part of a server frame: [u64 size][u64 zstd size][zstd][buffers]."""
        size = int.from_bytes(frame[:8], "little")
        packed = int.from_bytes(frame[8:16], "little")
        return zstandard.ZstdDecompressor().decompress(frame[16:16 + packed],
                                                       max_output_size=size)

    def saw(self, text: str, timeout: float = 30.0) -> bool:
        """Whether a frame carrying ``text`` arrives (msgpack keeps strings verbatim)."""
        needle = text.encode()
        deadline = time.monotonic() + timeout
        while not any(needle in f for f in self.frames):
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            try:
                self.frames.append(self._payload(self.ws.recv(timeout=min(left, 1.0))))
            except TimeoutError:
                pass
        return True

    def close(self) -> None:
        self.ws.close()


@pytest.fixture
def app(tmp_path):
    ns = argparse.Namespace(mesh=None, rings_file=None, rings=1, handles=None, session=None)
    a = EditorApp(build_state(ns), port=free_port(), export_dir=tmp_path,
                  max_upload_mb=64 / 1024)  # 64 KiB
    assert a.wait_idle(120)
    yield a
    a.stop()


@pytest.fixture
def client(app):
    c = Client(app.server.get_port())
    wait_for(lambda: len(app.server.get_clients()) == 1, 30, "the client to connect")
    yield c
    c.close()


def session_with(app, **changes) -> bytes:
    d = json.loads(json.dumps(app.state.to_dict()))
    d["handles"][1].update(changes)
    return json.dumps(d).encode()  # NaN is written as the JSON extension NaN


def test_nan_and_zero_rotation_sessions_are_refused_in_the_page(app, client):
    uuid = app.up_session._impl.uuid
    before = json.dumps(app.state.to_dict())
    client.upload(uuid, "t-nan", "nan.json", [session_with(app, position=[np.nan, 0, 0])])
    assert client.saw("expected a finite number, got nan"), "no notification in the page"
    client.upload(uuid, "t-q", "q.json", [session_with(app, wxyz=[0, 0, 0, 0])])
    assert client.saw("a rotation quaternion must not be zero")
    client.upload(uuid, "t-deep", "deep.json", [b"[" * 30_000 + b"]" * 30_000])
    assert client.saw("JSON too deeply nested")
    assert app.wait_idle(60)
    assert json.dumps(app.state.to_dict()) == before
    assert "⚠" in app.md_status.content
    # a good session still goes through the same path
    moved = app.state.handles[1].position + [0, 0, 0.25]
    client.upload(uuid, "t-ok", "ok.json", [session_with(app, position=moved.tolist())])
    wait_for(lambda: np.allclose(app.state.handles[1].position, moved), 30,
             "the good session to apply")
    assert client.saw("Session loaded")


def test_oversized_upload_dropped_as_it_arrives(app, client):
    uuid = app.up_session._impl.uuid
    states = app.server.gui._current_file_upload_states
    part = b" " * (512 * 1024)
    # declares 10 GiB: dropped at the start message, its parts are never buffered
    client.upload(uuid, "t-big", "big.json", [part] * 4, declared=10 * 2**30)
    assert client.saw("upload limit")
    wait_for(lambda: app.rejected_uploads == ["big.json"], 30, "the drop")
    assert "t-big" not in states
    # declares 100 bytes, then sends a 512 KiB part: dropped at that part
    client.upload(uuid, "t-liar", "liar.json", [part], declared=100)
    wait_for(lambda: app.rejected_uploads == ["big.json", "liar.json"], 30, "the second drop")
    assert "t-liar" not in states
    assert app.up_session.value.content == b""  # no upload callback ever saw the bytes


def test_the_panels_icons_come_from_one_opening_of_visers_archive(monkeypatch):
    """The start-up shortcut reads the same icons as viser does, opens the archive once,
    and leaves viser as it found it."""
    import zipfile

    from viser import _icons

    from arapkit.editor.panels import _icon_archive_opened_once

    names = ("plus", "pin", "upload", "download")
    expected = [_icons.svg_from_icon.__wrapped__(n) for n in names]
    opened: list = []
    real = zipfile.ZipFile

    class Counting(real):
        def __init__(self, *a, **k):
            opened.append(a[0])
            super().__init__(*a, **k)

    monkeypatch.setattr(zipfile, "ZipFile", Counting)
    with _icon_archive_opened_once():
        got = [_icons.svg_from_icon.__wrapped__(n) for n in names]
    assert got == expected and len(opened) == 1
    assert _icons.zipfile is zipfile
