"""Type I link figures (SPEC §8): a 132-code ALL_INFO exchange over a real pty pair at 9600 bit/s
against its wire time, and the software overhead per frame at 10× the line rate. Prints the
figures; docs/links.md quotes what it printed. (The Type II figures are benchmarks/links_type2.py.)

    .venv/bin/python benchmarks/links.py

Set-up: two `Type1Link`s, each in a `LinkRunner` on one asyncio loop; link A holds the pty master
(`PtyTransport`), link B opens the slave path through pyserial (`SerialTransport`); both senders
are paced at the line rate. One exchange = A sends ALL_INFO with 132 status bytes (a 143-byte
frame), B ACKs it (11 bytes); it is timed from `send()` to A's `AckReceived`. The wire time of
an exchange is (143 + 11) bytes × 10 bit / line rate: 160.4 ms at 9600 bit/s, 16.0 ms at 96000.
"""

from __future__ import annotations

import asyncio
import statistics
import sys
import time

from ktcs_bench.codec import get_profile
from ktcs_bench.transport import LinkRunner, PtyTransport, SerialTransport, VirtualBench
from ktcs_bench.type1 import AckReceived, LinkConfig, LinkEvent, MessageReceived, Type1Link

CODES = 132
PROFILE = get_profile("ktcs-type1")
STATUSES = bytes(i % 2 for i in range(CODES))


def wire_time(line_rate: float) -> float:
    return (PROFILE.frame_size(CODES) + PROFILE.frame_size(0)) * 10 / line_rate


async def exchanges(line_rate: float, repeats: int) -> list[float]:
    """Seconds per ALL_INFO + ACK exchange over a real pty pair paced at `line_rate`."""
    config = LinkConfig(line_rate=line_rate, longest_frame_data=CODES)
    acked = asyncio.Event()
    delivered = 0

    def on_a(now: float, event: LinkEvent) -> None:
        if isinstance(event, AckReceived):
            acked.set()

    def on_b(now: float, event: LinkEvent) -> None:
        nonlocal delivered
        if isinstance(event, MessageReceived) and event.message.data == STATUSES:
            delivered += 1

    with (
        PtyTransport("a", line_rate=line_rate) as ta,
        SerialTransport(ta.path, "b", line_rate=line_rate) as tb,
    ):
        a = Type1Link(PROFILE, config, "a", state_provider=lambda s, c: STATUSES)
        b = Type1Link(PROFILE, config, "b", state_provider=lambda s, c: STATUSES)
        ra, rb = LinkRunner(a, ta, on_a), LinkRunner(b, tb, on_b)
        tasks = [asyncio.create_task(r.run()) for r in (ra, rb)]
        while not (a.up and b.up and a.queued == 0 and b.queued == 0):  # start-up resync
            await asyncio.sleep(0.05)
        await asyncio.sleep(0.1)
        loop = asyncio.get_running_loop()
        samples = []
        message = a.message("ALL_INFO", statuses=list(STATUSES))
        for _ in range(repeats):
            acked.clear()
            t0 = loop.time()
            ra.send(message)
            await asyncio.wait_for(acked.wait(), 5)
            samples.append(loop.time() - t0)
        for r in (ra, rb):
            r.stop()
        await asyncio.gather(*tasks)
    assert delivered >= repeats, (delivered, repeats)
    return samples


def link_cpu_per_frame(n: int = 3000) -> float:
    """µs of CPU per data frame (encode, decode, ARQ, ACK both ways) on the virtual clock."""
    config = LinkConfig(line_rate=None)
    a = Type1Link(PROFILE, config, "a", state_provider=lambda s, c: STATUSES)
    b = Type1Link(PROFILE, config, "b", state_provider=lambda s, c: STATUSES)
    bench = VirtualBench(a, b, piece=1 << 16)
    bench.run_for(0.1)
    message = a.message("ALL_INFO", statuses=list(STATUSES))
    t0 = time.process_time()
    for _ in range(n):
        bench.send(a, message)
        bench.run_for(0.01, stop=lambda: a.queued == 0)
    return (time.process_time() - t0) / n * 1e6


def main() -> int:
    ok = True
    print(f"Type I link, {CODES}-code ALL_INFO exchange over a real pty pair (frame + ACK)")
    slow = asyncio.run(exchanges(9600.0, 10))
    wire = wire_time(9600.0)
    med, worst = statistics.median(slow), max(slow)
    ratio = med / wire
    ok &= ratio <= 1.10
    print(f"  9600 bit/s : wire {wire * 1e3:7.1f} ms   median {med * 1e3:7.1f} ms"
          f"   max {worst * 1e3:7.1f} ms   ratio {ratio:.3f} (goal <= 1.10)"
          f"   {'PASS' if ratio <= 1.10 else 'FAIL'}")  # fmt: skip

    fast = asyncio.run(exchanges(96000.0, 200))
    wire = wire_time(96000.0)
    med, p95 = statistics.median(fast), sorted(fast)[int(0.95 * len(fast)) - 1]
    over = (med - wire) * 1e3
    over95 = (p95 - wire) * 1e3
    ok &= over / 2 <= 5.0
    print(f"  96000 bit/s: wire {wire * 1e3:7.2f} ms   median {med * 1e3:7.2f} ms"
          f"   p95 {p95 * 1e3:7.2f} ms")  # fmt: skip
    print(f"  software overhead: {over:.2f} ms per exchange (p95 {over95:.2f}),"
          f" {over / 2:.2f} ms per frame (goal <= 5 ms)   {'PASS' if over / 2 <= 5.0 else 'FAIL'}")  # fmt: skip
    print(
        f"  link CPU (sans-I/O, both ends, no transport): {link_cpu_per_frame():.0f} µs per exchange"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
