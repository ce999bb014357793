"""A receive stream of any front end as blocks (:func:`rx_blocks`): a HackRF's own
``stream``, or a Pluto's receive buffer kept open from one block to the next.

libiio 0.x reports no overruns of a Pluto: its stream's ``last_stats.device_shortfalls``
is -1 (unknown), and only what the host counts (its ring) is exact there. An emulated
Pluto counts the blocks a late reader lost (``hil.pluto.context.OVERRUN_ATTR``): the
board's ``emulated_rx_loss`` holds them after the stream, ``(overruns, lost_blocks,
lost_samples)`` (None on a real board).
"""

from __future__ import annotations

import time
from collections.abc import Generator

import numpy as np

from hil.hackrf.stream import StreamStats
from hil.pluto.ad9361 import RX_FULL_SCALE
from hil.pluto.iio_access import receive_error, release_frames, rx_overrun_counts

PLUTO_BUFFER_SAMPLES = 1 << 18  # a Pluto's receive buffer at least (4 of them in the kernel)


def transfer_samples(radio, block_samples: int) -> int:
    """Samples of one transfer of ``radio``'s receive stream (:func:`rx_blocks`): what the
    driver may still hold when the air has passed."""
    if hasattr(radio, "stream"):
        return max(int(block_samples), getattr(radio, "rx_chunk_bytes", 0) // 2)
    return max(int(block_samples), PLUTO_BUFFER_SAMPLES)


def rx_blocks(radio, block_samples: int) -> Generator[np.ndarray, None, None]:
    """``[1, n]`` complex64 blocks (full scale 1.0) until the generator is closed; then the
    radio's ``last_stats`` hold what its stream did. A HackRF's blocks are
    ``block_samples`` long; a Pluto's are its receive buffers (:func:`transfer_samples`:
    a late reader has four of them to catch up in, as libiio keeps)."""
    if hasattr(radio, "stream"):
        return radio.stream(block_samples)
    return _pluto_blocks(radio, transfer_samples(radio, block_samples))


def _pluto_blocks(board, block_samples: int) -> Generator[np.ndarray, None, None]:
    """A ``hil.Pluto``'s receive buffer of ``block_samples``, refilled without pause."""
    sdr = board._sdr
    delivered, asked = 0, time.monotonic()
    try:
        sdr.rx_destroy_buffer()
        sdr.rx_buffer_size = int(block_samples)
        while True:
            asked = time.monotonic()
            x = np.asarray(sdr.rx())  # [block_samples] complex128, ADC counts
            board._receiving = True  # the stream is live once a buffer arrived
            delivered += len(x)
            yield (x / RX_FULL_SCALE).astype(np.complex64)[None, :]
    except GeneratorExit:
        raise
    except Exception as e:  # noqa: BLE001 - libiio raises OSError, pyadi Exception
        release_frames(e)
        raise receive_error(e, time.monotonic() - asked, board.timeout_ms) from e
    finally:
        board._receiving = False
        try:
            sdr.rx_destroy_buffer()
        except Exception:  # noqa: BLE001 - the connection may be gone already
            pass
        board.emulated_rx_loss = rx_overrun_counts(sdr)
        board.last_stats = StreamStats("rx", delivered)
