"""What libiio sees of an ADALM-Pluto: its IIO devices, channels and attribute names, as XML.

The three devices pyadi-iio's ``adi.Pluto`` needs (``ad9361-phy``, the RX ADC
``cf-ad9361-lpc`` and the TX DAC ``cf-ad9361-dds-core-lpc``) with a real Pluto's channel ids,
labels, scan elements (12-bit samples in 16-bit containers) and attribute names, and the
context XML (with its DTD) that iiod's ``PRINT`` returns.
"""

from __future__ import annotations

from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

PHY, RX_DEV, TX_DEV = "iio:device0", "iio:device1", "iio:device2"
DEVICE_NAMES = {PHY: "ad9361-phy", RX_DEV: "cf-ad9361-lpc", TX_DEV: "cf-ad9361-dds-core-lpc"}


@dataclass(frozen=True)
class Channel:
    """A channel of the context: id, direction, label, scan element and attribute names."""

    id: str
    output: bool
    attrs: tuple[str, ...]
    name: str | None = None
    scan_index: int | None = None
    scan_format: str | None = None


_PHY_RX = (
    "bb_dc_offset_tracking_en",
    "filter_fir_en",
    "gain_control_mode",
    "gain_control_mode_available",
    "hardwaregain",
    "hardwaregain_available",
    "quadrature_tracking_en",
    "rf_bandwidth",
    "rf_bandwidth_available",
    "rf_dc_offset_tracking_en",
    "rf_port_select",
    "rf_port_select_available",
    "rssi",
    "sampling_frequency",
    "sampling_frequency_available",
)
_PHY_TX = (
    "filter_fir_en",
    "hardwaregain",
    "hardwaregain_available",
    "rf_bandwidth",
    "rf_bandwidth_available",
    "rf_port_select",
    "rf_port_select_available",
    "rssi",
    "sampling_frequency",
    "sampling_frequency_available",
)
_LO = (
    "external",
    "fastlock_load",
    "fastlock_recall",
    "fastlock_save",
    "fastlock_store",
    "frequency",
    "frequency_available",
    "powerdown",
)
_PHY_DEV = (
    "calib_mode",
    "calib_mode_available",
    "ensm_mode",
    "ensm_mode_available",
    "filter_fir_config",
    "rx_path_rates",
    "trx_rate_governor",
    "trx_rate_governor_available",
    "tx_path_rates",
    "xo_correction",
    "xo_correction_available",
)
_ADC = (
    "calibbias",
    "calibphase",
    "calibscale",
    "samples_pscaled",
    "sampling_frequency",
    "sampling_frequency_available",
)
_DAC = ("calibphase", "calibscale", "sampling_frequency", "sampling_frequency_available")
_DDS = ("frequency", "phase", "raw", "sampling_frequency", "scale")

CHANNELS = {
    PHY: (
        Channel("altvoltage0", True, _LO, "RX_LO"),
        Channel("altvoltage1", True, _LO, "TX_LO"),
        Channel("voltage0", False, _PHY_RX),
        Channel("voltage0", True, _PHY_TX),
        Channel("out", False, ("voltage_filter_fir_en",)),
        Channel("temp0", False, ("input",)),
    ),
    RX_DEV: (
        Channel("voltage0", False, _ADC, None, 0, "le:S12/16>>0"),
        Channel("voltage1", False, _ADC, None, 1, "le:S12/16>>0"),
    ),
    TX_DEV: (
        Channel("voltage0", True, _DAC, None, 0, "le:S16/16>>0"),
        Channel("voltage1", True, _DAC, None, 1, "le:S16/16>>0"),
        Channel("altvoltage0", True, _DDS, "TX1_I_F1"),
        Channel("altvoltage1", True, _DDS, "TX1_I_F2"),
        Channel("altvoltage2", True, _DDS, "TX1_Q_F1"),
        Channel("altvoltage3", True, _DDS, "TX1_Q_F2"),
    ),
}
DEVICE_ATTRS = {PHY: _PHY_DEV, RX_DEV: (), TX_DEV: ()}
DEBUG_ATTRS = {PHY: ("loopback", "digital_tune"), RX_DEV: ("pseudorandom_err_check",), TX_DEV: ()}
BUFFER_ATTRS = ("data_available", "length_align_bytes", "watermark")
OVERRUN_ATTR = "osnerf_rx_overruns"
"""The emulated board's own debug attribute of ``cf-ad9361-lpc`` (a real Pluto has none, and
libiio 0.x reports no overruns): what its last receive buffer lost to a late reader
(``hil.emulation.pacing.BlockQueue``), as ``overruns lost_blocks lost_samples``."""
AIR_ATTR = "osnerf_air"
"""The emulated board's own debug attribute of ``ad9361-phy`` (a real Pluto has none): its
air as :func:`air_setting` text, written by the host before a burst (``osnerf ota``)."""


def air_setting(channel, ppm: float, seed: int) -> str:
    """The text of :data:`AIR_ATTR`: the ``hil.AirChannel`` from TX to RX, the board's
    crystal error in ppm (LOs and sample clock alike) and the noise seed, as JSON."""
    import json

    return json.dumps({"air": json.loads(channel.to_json()), "ppm": ppm, "seed": seed})


_DTD = (
    "<!DOCTYPE context ["
    "<!ELEMENT context (device | context-attribute)*>"
    "<!ELEMENT context-attribute EMPTY>"
    "<!ELEMENT device (channel | attribute | debug-attribute | buffer-attribute)*>"
    "<!ELEMENT channel (scan-element?, attribute*)>"
    "<!ELEMENT attribute EMPTY>"
    "<!ELEMENT scan-element EMPTY>"
    "<!ELEMENT debug-attribute EMPTY>"
    "<!ELEMENT buffer-attribute EMPTY>"
    "<!ATTLIST context name CDATA #REQUIRED description CDATA #IMPLIED>"
    "<!ATTLIST context-attribute name CDATA #REQUIRED value CDATA #REQUIRED>"
    "<!ATTLIST device id CDATA #REQUIRED name CDATA #IMPLIED label CDATA #IMPLIED>"
    "<!ATTLIST channel id CDATA #REQUIRED type (input|output) #REQUIRED name CDATA #IMPLIED>"
    "<!ATTLIST scan-element index CDATA #REQUIRED format CDATA #REQUIRED scale CDATA #IMPLIED>"
    "<!ATTLIST attribute name CDATA #REQUIRED filename CDATA #IMPLIED value CDATA #IMPLIED>"
    "<!ATTLIST debug-attribute name CDATA #REQUIRED value CDATA #IMPLIED>"
    "<!ATTLIST buffer-attribute name CDATA #REQUIRED value CDATA #IMPLIED>"
    "]>"
)


def find_channel(dev: str, chan_id: str | None, output: bool) -> Channel | None:
    """The channel ``chan_id`` of ``dev`` in that direction, or None."""
    for ch in CHANNELS.get(dev, ()):
        if ch.id == chan_id and ch.output == output:
            return ch
    return None


def context_xml(
    context_attrs: dict[str, str], description: str, debug_attrs: dict | None = None
) -> str:
    """The context as libiio 0.x's XML, with ``context_attrs`` as its context attributes
    and ``debug_attrs`` (default :data:`DEBUG_ATTRS`) as each device's debug attributes."""
    debug_attrs = DEBUG_ATTRS if debug_attrs is None else debug_attrs
    out = [
        '<?xml version="1.0" encoding="utf-8"?>',
        _DTD,
        f'<context name="xml" description={quoteattr(description)} >',
    ]
    out += [
        f"<context-attribute name={quoteattr(k)} value={quoteattr(v)} />"
        for k, v in context_attrs.items()
    ]
    for dev, name in DEVICE_NAMES.items():
        out.append(f'<device id="{dev}" name="{name}" >')
        for ch in CHANNELS[dev]:
            label = f" name={quoteattr(ch.name)}" if ch.name else ""
            out.append(
                f'<channel id="{ch.id}"{label} type="{"output" if ch.output else "input"}" >'
            )
            if ch.scan_index is not None:
                assert ch.scan_format is not None  # every scan element has a format
                fmt = ch.scan_format.replace(">", "&gt;")
                out.append(
                    f'<scan-element index="{ch.scan_index}" format="{fmt}" scale="1.000000" />'
                )
            prefix = f"{'out' if ch.output else 'in'}_{ch.id}"
            out += [f'<attribute name="{a}" filename="{prefix}_{a}" />' for a in ch.attrs]
            out.append("</channel>")
        out += [f'<attribute name="{a}" />' for a in DEVICE_ATTRS[dev]]
        if dev != PHY:
            out += [f'<buffer-attribute name="{a}" />' for a in BUFFER_ATTRS]
        out += [f'<debug-attribute name="{a}" />' for a in debug_attrs[dev]]
        out.append("</device>")
    out.append("</context>")
    return "".join(out)
