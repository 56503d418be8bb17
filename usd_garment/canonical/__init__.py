"""Canonical space: simulated garments projected to the unposed, deshaped space of the garment
model (the paper's Sec. 3.3), and the inverse-skinning baselines it is compared with."""
