"""A receive stream of any front end as blocks (:func:`rx_blocks`): a HackRF's own
``stream``, or a Pluto's receive buffer kept open from one block to the next.

libiio 0.x reports no overruns of a Pluto: its stream's ``last_stats.device_shortfalls``
is -1 (unknown), and only what the host counts (its ring) is exact there.
"""

from __future__ import annotations

import time
from collections.abc import Generator

import numpy as np

from hil.ad9361 import RX_FULL_SCALE
from hil.iio_access import receive_error, release_frames
from hil.stream import StreamStats


def rx_blocks(radio, block_samples: int) -> Generator[np.ndarray, None, None]:
    """``[1, block_samples]`` complex64 blocks (full scale 1.0) until the generator is
    closed; then the radio's ``last_stats`` hold what its stream did."""
    if hasattr(radio, "stream"):
        return radio.stream(block_samples)
    return _pluto_blocks(radio, block_samples)


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
        board.last_stats = StreamStats("rx", delivered)
