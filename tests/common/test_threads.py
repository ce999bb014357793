"""common.one_blas_thread: a receive path runs with numpy's BLAS pool at one thread, and the
user's setting is back afterwards."""

import numpy as np
from threadpoolctl import threadpool_info, threadpool_limits

import phy
from common import one_blas_thread


def _blas_threads() -> set[int]:
    return {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}


def test_the_pool_is_one_thread_inside_and_the_users_outside():
    np.ones((8, 8)) @ np.ones((8, 8))  # BLAS loaded
    seen = {}

    @one_blas_thread
    def inner():
        seen["inside"] = _blas_threads()
        nested()

    @one_blas_thread
    def nested():
        seen["nested"] = _blas_threads()

    with threadpool_limits(limits=2, user_api="blas"):  # what a user's environment says
        inner()
        after = _blas_threads()
    assert seen["inside"] == seen["nested"] == {1} and after == {2}


def test_the_receiver_chain_runs_with_one_blas_thread(monkeypatch):
    from phy import receiver

    seen = []

    def find_preambles(*args):  # the chain's first step, as the chain runs it
        seen.append(_blas_threads())
        return []

    monkeypatch.setattr(receiver, "find_preambles", find_preambles)
    capture = np.zeros(50_000, np.complex64)
    with threadpool_limits(limits=2, user_api="blas"):
        phy.find_frames(capture)
        phy.receive_frame(capture, num_symbols=64)
        phy.receive_frames(capture, num_symbols=64)
    assert seen == [{1}, {1}, {1}]
