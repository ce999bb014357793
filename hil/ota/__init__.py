"""Over the air: bursts and streams of phy frames through any radio, their header, receiver and
SigMF captures."""
