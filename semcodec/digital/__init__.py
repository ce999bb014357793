"""The digital baselines: classic image codecs, their files through CRC + 5G LDPC + QAM, and the
MCS choice from the calibration table."""
