"""The HackRF One on pure pyusb: its USB protocol, driver, settings, receive stream and the
loopback without USB."""
