"""Signals taken inside a deferred block are recorded there and answered at its end."""

from __future__ import annotations

import signal

import pytest

from bodyfusion.base import interrupts
from bodyfusion.base.interrupts import RECEIVED, Terminated, deferred, deferring


@pytest.fixture(autouse=True)
def no_signal_taken():
    saved = set(RECEIVED)
    RECEIVED.clear()
    yield
    RECEIVED.clear()
    RECEIVED.update(saved)


def test_a_signal_inside_a_deferred_block_is_answered_at_its_end_not_before():
    done = []
    with pytest.raises(Terminated):
        with deferred():
            assert deferring()
            RECEIVED.add(signal.SIGTERM)  # what the command line's handler does inside
            done.append("the rest of the block")
    assert done == ["the rest of the block"] and not deferring()


def test_nested_blocks_answer_at_the_outermost_end():
    with pytest.raises(KeyboardInterrupt):
        with deferred():
            with deferred():
                RECEIVED.add(signal.SIGINT)
            assert deferring()  # the inner end did not answer


def test_a_signal_taken_before_the_block_is_not_answered_by_it():
    RECEIVED.add(signal.SIGINT)  # an earlier command's, in this process
    with deferred():
        pass
    assert not deferring() and interrupts._DEFERRED == [0]


def test_a_block_that_raises_raises_its_own_error():
    with pytest.raises(ValueError):
        with deferred():
            RECEIVED.add(signal.SIGTERM)
            raise ValueError("its own")
