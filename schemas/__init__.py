"""Codeless USD schema of usd-garment (SmplBodyAPI, GarmentAPI): data files only."""
