"""Recordings -> physical quantities: Ka, filters, spectra, aE -> omega2/epsilon2, cycles."""
