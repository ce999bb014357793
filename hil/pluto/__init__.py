"""The ADALM-Pluto through pyadi-iio on libiio: the AD9361's numbers, what libiio sees of the
board, and the driver."""
