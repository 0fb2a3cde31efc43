"""ndds-python adapter for bench.py.

Loopback only: the participants use the domain's daemon, and the first process (side "a")
embeds one when none runs; a daemon uses 127.0.0.1 unless told otherwise (`--interface`),
and the embedded one takes the defaults, so discovery and data stay on lo. The domain is
PYBENCH_DDS_DOMAIN (one per harness run).

Batching: the throughput source packs samples into datagrams of up to 8 KiB (or 1 ms), as
zenoh batches on its TCP link by default; ping and pong send each sample on its own.

The sample type is a dataclass with one `bytes` field (Rust `serde_bytes::ByteBuf`): 64
payload bytes, written as a length byte and the bytes.

Receive styles: ping, pong and the sink all pull with `Consumer.recv(timeout)`, which waits
without the GIL; `pull` was faster than a callback thread here, since a callback thread only
adds a hand-over between threads on top of the same receive.
"""

from __future__ import annotations

import dataclasses
import os
from importlib import metadata
from typing import Callable, Optional

import ndds

NAME = "ndds"
ECHO_STYLE = "pull"
SINK_STYLE = "pull"


@dataclasses.dataclass
class Bench64:
    data: bytes


def library_version() -> str:
    try:
        return "ndds " + metadata.version("ndds")
    except metadata.PackageNotFoundError:
        return "ndds (source)"


class Publisher:
    def __init__(self, producer) -> None:
        write = producer.write
        self._producer = producer
        self.put = lambda payload: write(Bench64(payload))


class Subscriber:
    def __init__(self, consumer) -> None:
        self._consumer = consumer
        self._recv = consumer.recv

    def recv(self, timeout: Optional[float]) -> Optional[bytes]:
        try:
            return self._recv(timeout).value.data
        except ndds.Timeout:
            return None


class Node:
    def __init__(self, side: str, port: int) -> None:
        self._side = side
        self._participant = None

    def open(self) -> None:
        domain = int(os.environ.get("PYBENCH_DDS_DOMAIN", "0"))
        self._participant = ndds.Participant(domain=domain, name=f"bench-{self._side}")

    def publisher(self, topic: str, reliable: bool = True) -> Publisher:
        # The throughput source batches (at most 1 ms or 8 KiB per datagram), as zenoh's
        # transport does by default; the round-trip topics send each sample at once.
        batching = (0.001, 8192) if topic == "bench/throughput" else None
        producer = self._participant.producer(topic, Bench64, reliable=reliable, batching=batching)
        return Publisher(producer)

    def subscriber(self, topic: str, reliable: bool = True, on_data: Optional[Callable[[bytes], None]] = None):
        consumer = self._participant.consumer(
            topic, Bench64, reliable=reliable, depth=4096, history=4096 if reliable else None
        )
        if on_data is not None:
            consumer.on_sample(lambda sample: on_data(sample.value.data))
        return Subscriber(consumer)

    def close(self) -> None:
        self._participant = None
