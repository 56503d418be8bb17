"""The ``usd-garment`` command line (installed as ``usd_garment.cli``)."""
