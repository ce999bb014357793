"""The GNU Radio bridge: :class:`ZmqRadio` (gr-zeromq's stream format) and the flowgraphs of
``gnuradio/``, compiled by ``grcc`` and run on Debian's python3 in their own process."""
