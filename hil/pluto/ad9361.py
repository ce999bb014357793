"""The AD9361 (as on an ADALM-Pluto) in numbers: ranges and how its driver quantises values.

Pure functions, modelled on the Linux ``ad9361`` driver's arithmetic on the Pluto's 40 MHz
reference, so an emulated board reads values back as the part would:

* LO frequency: the RF PLL's VCO (6-12 GHz) divided by 2^(d+1); the VCO is the reference
  times ``integer + fract / 8388593``; the read-back is the PLL's output, rounded down to 1 Hz.
* Sample rate: the baseband PLL (715-1430 MHz, fractional-N with modulus 2088960) divided
  by integer dividers (ADC, then three half-band stages, then the optional FIR decimation),
  each rounded down to 1 Hz.
* RX gain: whole dB in the gain table's range (which depends on the LO); the driver keeps
  the integer part. TX attenuation: 0.25 dB steps in [0, 89.75] dB, truncated to the step.
* RF bandwidth: any integer in range (the driver keeps the value it tuned the filters to).

Ranges are a stock Pluto's AD9363: LO 325 MHz-3.8 GHz, RF bandwidth 200 kHz-20 MHz, sample
rate 2.083-61.44 MS/s (520.833 kS/s with the FIR decimating by 4).

Sample containers (the host's int16 I and Q): the ADC's 12-bit samples arrive sign-extended
(full scale 2048); the DAC takes its 12 bits from the container's most significant bits.
pyadi-iio's ``tx()`` casts the host's numbers to int16 with ``astype`` (no clipping), so a
full-scale 1.0 must map to 32767, the largest int16: 32768 would wrap to -32768. The DAC
keeps ``32767 >> 4 = 2047``, its largest code, so nothing of the range is lost.
"""

from __future__ import annotations

import math

RX_FULL_SCALE = 2048  # 12-bit ADC samples, sign-extended in int16 containers
TX_FULL_SCALE = 32767  # int16 container of the 12-bit DAC (its 12 MSBs): int16's maximum
REFERENCE_HZ = 40_000_000
RFPLL_MODULUS = 8388593
BBPLL_MODULUS = 2088960
VCO_RANGE_HZ = (6_000_000_000, 12_000_000_000)
BBPLL_RANGE_HZ = (715_000_000, 1_430_000_000)
MAX_ADC_CLOCK_HZ = 640_000_000
MIN_ADC_CLOCK_HZ = BBPLL_RANGE_HZ[0] // 64

LO_RANGE_HZ = (325_000_000, 3_800_000_000)
RF_BANDWIDTH_RANGE_HZ = (200_000, 20_000_000)
SAMPLE_RATE_RANGE_HZ = (2_083_333, 61_440_000)  # without the FIR decimation
FIR_SAMPLE_RATE_MIN_HZ = 520_833  # with the FIR decimating by 4
TX_ATTENUATION_RANGE_DB = (0.0, 89.75)
TX_ATTENUATION_STEP_DB = 0.25
GAIN_CONTROL_MODES = ("manual", "fast_attack", "slow_attack", "hybrid")
# The Pluto's gains in an over-the-air run unless told otherwise (an emulated board's AGC
# settles on the receive gain, and its manual mode starts there).
DEFAULT_RX_GAIN_DB = 30
DEFAULT_TX_GAIN_DB = -10.0

# (ADC divider, R2, R1, RF half-band decimations), fastest oversampling first
_CLOCK_DIVIDERS = (
    (12, 3, 2, 2),
    (8, 2, 2, 2),
    (6, 3, 1, 2),
    (4, 2, 2, 1),
    (3, 3, 1, 1),
    (2, 2, 1, 1),
    (1, 1, 1, 1),
)


def lo_frequency_hz(value_hz: int) -> int:
    """The LO frequency the RF PLL produces for a request, Hz (rounded down to 1 Hz).

    Raises:
        ValueError: outside :data:`LO_RANGE_HZ`.
    """
    f = int(value_hz)
    lo, hi = LO_RANGE_HZ
    if not lo <= f <= hi:
        raise ValueError(f"LO frequency must be in [{lo}, {hi}] Hz, got {value_hz!r}")
    div = 0  # VCO = f * 2^(div + 1) must land in [6, 12] GHz
    while (f << (div + 1)) < VCO_RANGE_HZ[0]:
        div += 1
    vco = f << (div + 1)
    integer, rem = divmod(vco, REFERENCE_HZ)
    fract = (rem * RFPLL_MODULUS + REFERENCE_HZ // 2) // REFERENCE_HZ
    if fract >= RFPLL_MODULUS:
        integer, fract = integer + 1, fract - RFPLL_MODULUS
    vco_out = REFERENCE_HZ * integer + (REFERENCE_HZ * fract) // RFPLL_MODULUS
    return vco_out >> (div + 1)


def lo_step_hz(value_hz: int) -> float:
    """The LO's frequency resolution at ``value_hz``: reference / modulus / 2^(div + 1), Hz."""
    div = 0
    while (int(value_hz) << (div + 1)) < VCO_RANGE_HZ[0]:
        div += 1
    return REFERENCE_HZ / RFPLL_MODULUS / 2 ** (div + 1)


def bbpll_rate_hz(target_hz: int) -> int:
    """The baseband PLL's rate for a target: reference * (integer + fract / 2088960), floor."""
    integer, rem = divmod(int(target_hz), REFERENCE_HZ)
    fract = (rem * BBPLL_MODULUS + REFERENCE_HZ // 2) // REFERENCE_HZ
    return REFERENCE_HZ * integer + (REFERENCE_HZ * fract) // BBPLL_MODULUS


def clock_chain(sample_rate_hz: int, fir_decimation: int = 1) -> dict[str, int]:
    """The receive clock chain for a sample rate, as ``rx_path_rates`` lists it.

    Args:
        sample_rate_hz: requested rate, S/s.
        fir_decimation: 1 (FIR off), 2 or 4.
    Returns:
        ``{"BBPLL", "ADC", "R2", "R1", "RF", "RXSAMP"}`` in Hz; ``RXSAMP`` is what
        ``sampling_frequency`` reads back.
    Raises:
        ValueError: no divider chain reaches the rate (out of range).
    """
    rate = int(sample_rate_hz)
    lo = FIR_SAMPLE_RATE_MIN_HZ if fir_decimation == 4 else SAMPLE_RATE_RANGE_HZ[0]
    if fir_decimation not in (1, 2, 4):
        raise ValueError(f"fir_decimation must be 1, 2 or 4, got {fir_decimation!r}")
    if not lo <= rate <= SAMPLE_RATE_RANGE_HZ[1]:
        raise ValueError(
            f"sampling_frequency must be in [{lo}, {SAMPLE_RATE_RANGE_HZ[1]}] S/s "
            f"(FIR decimation {fir_decimation}), got {sample_rate_hz!r}"
        )
    clkrf = rate * fir_decimation
    chosen = None
    for row in _CLOCK_DIVIDERS[1:]:  # the driver's "nominal" rate governor skips row 0
        adc = clkrf * row[0]
        if MIN_ADC_CLOCK_HZ <= adc <= MAX_ADC_CLOCK_HZ:
            chosen = (row, adc)
            break
    if chosen is None:
        raise ValueError(f"sampling_frequency {rate}: no ADC clock divider chain reaches it")
    row, adc = chosen
    div = 64
    while True:  # the largest power-of-two multiple of the ADC clock that the BBPLL can make
        bbpll_target = adc * div
        div >>= 1
        if bbpll_target <= BBPLL_RANGE_HZ[1] or div < 2:
            break
    bbpll = bbpll_rate_hz(bbpll_target)
    adc_hz = bbpll // (bbpll_target // adc)
    r2 = adc_hz // row[1]
    r1 = r2 // row[2]
    rf = r1 // row[3]
    return {
        "BBPLL": bbpll,
        "ADC": adc_hz,
        "R2": r2,
        "R1": r1,
        "RF": rf,
        "RXSAMP": rf // fir_decimation,
    }


def rx_gain_range_db(lo_hz: float) -> tuple[int, int]:
    """The manual RX gain range of the gain table in use at this LO, dB (1 dB steps)."""
    if lo_hz <= 1_300_000_000:
        return (1, 77)
    if lo_hz <= 4_000_000_000:
        return (-3, 71)
    return (-10, 62)


def rx_gain_db(value_db: float, lo_hz: float) -> int:
    """The RX gain the driver keeps: the integer part of the value, in range.

    Raises:
        ValueError: not finite or outside :func:`rx_gain_range_db`.
    """
    lo, hi = rx_gain_range_db(lo_hz)
    v = float(value_db)
    if not math.isfinite(v) or not lo <= math.trunc(v) <= hi:
        raise ValueError(f"RX hardwaregain must be in [{lo}, {hi}] dB at this LO, got {value_db!r}")
    return math.trunc(v)


def tx_gain_db(value_db: float) -> float:
    """The TX gain (minus the attenuation) the driver keeps: 0.25 dB steps, truncated toward 0.

    Raises:
        ValueError: not finite, positive or below -89.75 dB.
    """
    v = float(value_db)
    lo, hi = TX_ATTENUATION_RANGE_DB
    if not math.isfinite(v) or not -hi <= v <= lo:
        raise ValueError(f"TX hardwaregain must be in [{-hi:g}, 0] dB, got {value_db!r}")
    millidb = round(-v * 1000)
    return -(millidb // 250) * TX_ATTENUATION_STEP_DB


def rf_bandwidth_hz(value_hz: int) -> int:
    """The RF bandwidth kept for a request, Hz (integers in range)."""
    lo, hi = RF_BANDWIDTH_RANGE_HZ
    if int(value_hz) != value_hz or not lo <= value_hz <= hi:
        raise ValueError(f"rf_bandwidth must be an integer in [{lo}, {hi}] Hz, got {value_hz!r}")
    return int(value_hz)


def integer_hz(value: float, name: str) -> int:
    """A positive frequency as the whole Hz the driver's attributes take (``name`` for the
    ``ValueError`` otherwise)."""
    v = float(value)
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be a positive frequency in Hz, got {value!r}")
    return int(round(v))
