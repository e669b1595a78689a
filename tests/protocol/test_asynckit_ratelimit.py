"""The one token bucket: paces the daemons' link, refuses excess on the server's asset socket."""

from __future__ import annotations

import pytest

from asynckit.ratelimit import TokenBucket


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_token_bucket_allows_a_burst_then_paces_to_the_rate() -> None:
    clock = FakeClock()
    bucket = TokenBucket(rate=150, burst=300, clock=clock)
    assert all(bucket.delay() == 0 for _ in range(300))
    wait = bucket.delay()
    assert wait == pytest.approx(1 / 150)
    clock.now += 1.0
    assert sum(1 for _ in range(1000) if bucket.delay() == 0) == 150
    clock.now += 1000.0
    assert sum(1 for _ in range(1000) if bucket.delay() == 0) == 300  # never above the burst


def test_token_bucket_slows_down_when_told() -> None:
    clock = FakeClock()
    bucket = TokenBucket(rate=150, burst=300, clock=clock)
    bucket.slow_down()
    assert bucket.rate == 75 and bucket.burst == 150
    assert sum(1 for _ in range(1000) if bucket.delay() == 0) == 150
    for _ in range(20):
        bucket.slow_down()
    assert bucket.rate == 1.0 and bucket.burst == 1.0


def test_token_bucket_take_refuses_without_taking() -> None:
    """The server's use: `take` says no past the burst, and a refusal costs nothing."""
    clock = FakeClock()
    bucket = TokenBucket(rate=10, burst=2, clock=clock)
    assert bucket.take() and bucket.take()
    assert not bucket.take() and not bucket.take()
    clock.now += 0.15  # 1.5 tokens back
    assert bucket.take()
    assert not bucket.take()


def test_token_bucket_refuses_a_burst_under_one() -> None:
    with pytest.raises(ValueError):
        TokenBucket(rate=10, burst=0.5)
