"""Emulated radios and the air between them: channels, time-varying paths, the medium, emulated
HackRFs (a pyusb backend, in-process or in a process of their own) and an emulated Pluto served
over iiod."""
