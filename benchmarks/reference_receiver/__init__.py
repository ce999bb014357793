"""The frozen reference receiver: the frame search and receive chain as they were before the
vectorised implementation in ``phy``, kept to time it against (``benchmarks.receiver_timing``)
and to check that both find the same frames and decode the same bits
(``tests/phy/test_receiver_equivalence.py``). Not used by any run."""
