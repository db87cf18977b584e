"""The web server in this process on a free loopback port: page, flow control, read-only.

A page gets a frame only after asking for it ("next"), the newest one, converted only then;
a page that never asks costs no encoding; nothing but GET and the WebSocket is served.
"""
import asyncio
import json
import socket

import aiohttp
import pytest
import viewer_messages as msgs

from tactile_sl_viewer.assembly import FrameAssembler
from tactile_sl_viewer.packets import PacketBuilder, unpack
from tactile_sl_viewer.web import ViewerServer

S = 1_000_000_000


class Source:
    def __init__(self):
        self.assembler = FrameAssembler()
        self.seeks = []

    def hello(self):
        return {"mode": "bag", "frames": 3}

    def seek(self, index):
        self.seeks.append(index)

    def extra(self):
        return {"bag": {"index": 0}}


def add_frame(source, stamp):
    for part, msg in (("image", msgs.image(stamp)), ("points", msgs.points(stamp)),
                      ("wrench", msgs.wrench(stamp, force=(0, 0, -stamp / S))),
                      ("field", msgs.field(stamp, {(2, 2): -0.01}))):
        source.assembler.add(part, msg, stamp)


@pytest.fixture
def server():
    source = Source()
    builder = PacketBuilder(msgs.PAD, "tactile")
    srv = ViewerServer(source, builder, "127.0.0.1", 0, max_clients=2, idle_s=0.3)
    srv.start()
    yield srv
    srv.stop()


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, 30))


def test_the_page_and_nothing_else_is_served(server):
    async def go():
        async with aiohttp.ClientSession() as http:
            async with http.get(server.url) as r:
                assert r.status == 200 and "text/html" in r.headers["Content-Type"]
                assert "default-src 'self'" in r.headers["Content-Security-Policy"]
                assert 'id="map"' in await r.text()
            for path in ("viewer.js", "viewer.css"):
                async with http.get(server.url + path) as r:
                    assert r.status == 200
            async with http.post(server.url, data=b"x") as r:
                assert r.status == 405
            for path in ("static/index.html", "..%2f..%2fetc/passwd", "config"):
                async with http.get(server.url + path) as r:
                    assert r.status == 404
    run(go())


def test_frames_come_one_per_request_newest_first(server):
    source = server.source

    async def go():
        async with aiohttp.ClientSession() as http:
            async with http.ws_connect(server.url + "ws") as ws:
                hello = json.loads((await ws.receive()).data)
                assert hello == {"type": "hello", "mode": "bag", "frames": 3}
                for k in (1, 2, 3):
                    add_frame(source, k * S)
                await asyncio.sleep(0.2)
                assert server.builder.encoded == 0     # nobody asked: nothing encoded
                await ws.send_str(json.dumps({"type": "next", "map": "pressure"}))
                header, blobs = unpack((await ws.receive()).data)
                assert header["stamp"] == "3.000000000"  # the newest; 1 and 2 never sent
                assert header["wrench"]["force"][2] == -3.0
                assert "image" in blobs and "pressure" in blobs and header["bag"] == {"index": 0}
                # nothing new: after idle_s the figures only
                await ws.send_str(json.dumps({"type": "next"}))
                header, _ = unpack((await ws.receive()).data)
                assert "stamp" not in header and "stats" in header
                # a new frame while the page waits is sent at once
                await ws.send_str(json.dumps({"type": "next"}))
                await asyncio.sleep(0.05)
                add_frame(source, 4 * S)
                header, _ = unpack((await ws.receive()).data)
                assert header["stamp"] == "4.000000000"
                assert server.builder.encoded == 2
                await ws.send_str(json.dumps({"type": "seek", "index": 2}))
                await ws.send_str(json.dumps({"type": "next"}))
                await ws.receive()
                assert source.seeks == [2]
    run(go())


def test_a_page_that_speaks_out_of_turn_is_closed(server):
    async def go():
        async with aiohttp.ClientSession() as http:
            for bad in ("not json", json.dumps({"type": "set_parameter", "name": "x"}),
                        json.dumps([1, 2])):
                async with http.ws_connect(server.url + "ws") as ws:
                    await ws.receive()                     # hello
                    await ws.send_str(bad)
                    msg = await ws.receive()
                    assert msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED)
    run(go())


def test_cross_origin_pages_and_too_many_pages_are_refused(server):
    async def go():
        async with aiohttp.ClientSession() as http:
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                await http.ws_connect(server.url + "ws", origin="http://evil.example")
            assert refused.value.status == 403
            first = await http.ws_connect(server.url + "ws")
            second = await http.ws_connect(server.url + "ws")
            await first.receive()
            await second.receive()
            with pytest.raises(aiohttp.WSServerHandshakeError) as full:
                await http.ws_connect(server.url + "ws")
            assert full.value.status == 503
            await first.close()
            await second.close()
    run(go())


def test_a_port_in_use_is_one_clear_error():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        srv = ViewerServer(Source(), PacketBuilder(msgs.PAD), "127.0.0.1", port)
        with pytest.raises(OSError, match=f"127.0.0.1:{port}"):
            srv.start()
        srv.stop()


def test_each_page_gets_at_most_max_rate_frames_a_second_and_a_live_change_applies():
    """Frames arrive at 100 Hz and the page asks again as soon as one lands: with
    ``max_rate`` 5 it gets about 5 a second (the newest each time); with 0 (set while it
    is connected) as many as it can read."""
    source = Source()
    srv = ViewerServer(source, PacketBuilder(msgs.PAD, "tactile"), "127.0.0.1", 0,
                       idle_s=0.3, max_rate=5.0)
    srv.start()
    window = 2.0

    async def frames_in(ws, seconds):
        loop = asyncio.get_running_loop()
        end, count, stamps = loop.time() + seconds, 0, []
        while loop.time() < end:
            await ws.send_str(json.dumps({"type": "next"}))
            header, _ = unpack((await ws.receive()).data)
            if "stamp" in header:
                count += 1
                stamps.append(header["stamp"])
        return count, stamps

    async def go():
        stop = asyncio.Event()

        async def camera():                  # a new frame every 10 ms
            k = 1
            while not stop.is_set():
                add_frame(source, k * S)
                k += 1
                await asyncio.sleep(0.01)

        feeder = asyncio.create_task(camera())
        try:
            async with aiohttp.ClientSession() as http:
                async with http.ws_connect(server_url(srv)) as ws:
                    await ws.receive()                       # hello
                    capped, stamps = await frames_in(ws, window)
                    srv.max_rate = 0.0
                    await frames_in(ws, 0.3)                 # the change lands
                    uncapped, _ = await frames_in(ws, window)
        finally:
            stop.set()
            await feeder
        return capped, stamps, uncapped

    try:
        capped, stamps, uncapped = run(go())
    finally:
        srv.stop()
    # 5/s over 2 s: the first at once, then one every 0.2 s (11 at most, with slack for the
    # last request in flight); a loaded machine may send fewer, never more
    assert 5 <= capped <= 12, capped
    assert len(set(stamps)) == len(stamps)             # never the same frame twice
    assert uncapped > 2 * capped, (capped, uncapped)


def server_url(srv):
    return srv.url + "ws"
