"""Devices (driver interface, simulated stand, NI-DAQmx), the recorder, calibration."""
