"""Per-sample cost of the Python binding in one process: 100 000 `write`s of a 64-byte
dataclass (batched, so the socket is not what is measured), then as many `try_recv`s of the
queued samples. Uses an embedded daemon on loopback (domain 199 unless NDDS_DOMAIN is set).

    python ndds-python/bench/inprocess.py
"""

import dataclasses
import os
import time

import ndds


@dataclasses.dataclass
class Bench64:
    data: bytes


def main() -> None:
    domain = int(os.environ.get("NDDS_DOMAIN", "199"))
    p = ndds.Participant(embedded="always", domain=domain)
    producer = p.producer("bench/inprocess", Bench64, batching=(0.001, 8192))
    consumer = p.consumer("bench/inprocess", Bench64, depth=200_000)
    assert producer.wait_for_consumers(1)
    n = 100_000
    payload = bytes(64)
    start = time.perf_counter()
    for _ in range(n):
        producer.write(Bench64(payload))
    producer.flush()
    written = time.perf_counter() - start
    time.sleep(0.5)
    got = 0
    start = time.perf_counter()
    while True:
        sample = consumer.try_recv()
        if sample is None:
            break
        sample.value.data
        got += 1
    taken = time.perf_counter() - start
    print(f"write {1e9 * written / n:.0f} ns/sample (the dataclass built included), "
          f"try_recv {1e9 * taken / max(got, 1):.0f} ns/sample, {got} of {n} received")


if __name__ == "__main__":
    main()
