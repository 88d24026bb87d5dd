"""Importers for public surgical-motion data sets, mapped onto the same metric pipeline."""
