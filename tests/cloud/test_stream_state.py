"""The stream state machine without sockets: any bytes give a reply or a ProtocolError."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from darkread.cloud.auth import ENVIRONMENT_ADMIN, KeyRing
from darkread.cloud.context import AppContext
from darkread.cloud.live import LivePages
from darkread.cloud.ocr.base import OcrResult
from darkread.cloud.prometheus import Metrics
from darkread.cloud.settings import Settings
from darkread.cloud.store import SqliteStore
from darkread.cloud.stream import StreamConnection, StreamState, _Pending
from darkread.proto.errors import ProtocolError, UnexpectedMessageError
from darkread.proto.messages import Ack, Hello, Welcome, encode


class NoOcr:
    name = "none"

    def read(self, image: np.ndarray) -> OcrResult:
        raise AssertionError("not used")

    def ready(self) -> bool:
        return True


@pytest.fixture(scope="module")
def context(tmp_path_factory: pytest.TempPathFactory) -> Iterator[AppContext]:
    data = Path(tmp_path_factory.mktemp("state"))
    store = SqliteStore(data)
    settings = Settings(_env_file=None, data_dir=data, max_message_bytes=4096)
    pages = LivePages(store, NoOcr())
    yield AppContext(settings=settings, store=store, metrics=Metrics(), ocr=NoOcr(), pages=pages,
                     keys=KeyRing(data / "keys.json"))
    asyncio.run(pages.close())
    asyncio.run(store.close())


HELLO = Hello(device_id="d", session_id="fuzz", mode="frames", sensor=(1280, 720), fovea=(100, 200))
message_maps = st.dictionaries(
    st.sampled_from(["type", "seq", "v", "shape", "bits", "t_us", "px", "stats", "session_id", "frame_id", "origin"]),
    st.one_of(
        st.sampled_from(["frame", "page", "gaze", "heartbeat", "hello", "ack", "error", "welcome"]),
        st.integers(-(2**63), 2**64 - 1),  # everything msgpack can encode
        st.binary(max_size=40),
        st.lists(st.integers(-5, 300), max_size=5),
        st.dictionaries(st.text(max_size=5), st.floats(allow_nan=False), max_size=3),
    ),
    max_size=8,
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.one_of(st.binary(max_size=200), message_maps.map(lambda m: msgpack.packb(m, use_bin_type=True))))
def test_anything_after_hello_is_handled_or_refused(context: AppContext, data: bytes) -> None:
    async def scenario() -> None:
        connection = StreamConnection(context, principal=ENVIRONMENT_ADMIN)
        assert isinstance(await connection.handle(encode(HELLO)), Welcome)
        assert connection.state is StreamState.STREAMING
        try:
            outgoing = await connection.handle(data)
        except ProtocolError:
            return
        if isinstance(outgoing, _Pending):
            result = await outgoing.result
            assert result.last_seq >= 0
        else:
            assert outgoing is None  # a heartbeat
        await context.pages.forget("fuzz")  # its pages belong to this event loop

    asyncio.run(scenario())


def test_only_hello_opens_a_connection(context: AppContext) -> None:
    async def scenario() -> None:
        connection = StreamConnection(context, principal=ENVIRONMENT_ADMIN)
        with pytest.raises(UnexpectedMessageError, match="expected hello"):
            await connection.handle(encode(Ack(seq=1)))
        assert connection.state is StreamState.AWAIT_HELLO

    asyncio.run(scenario())
