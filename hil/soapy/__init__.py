"""Every SDR with a SoapySDR module (USRP via SoapyUHD, HackRF, LimeSDR, bladeRF, RTL-SDR,
a SoapyRemote server): :class:`SoapyRadio` on Debian's python3-soapysdr."""
