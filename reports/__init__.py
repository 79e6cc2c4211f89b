"""Comparison metrics, figures, HTML/PDF/JSON reports."""
