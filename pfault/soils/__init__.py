"""Soils that remember: the materials given a compression law with memory (pfault.physics.soil) as a term of the
equations (``term.SoilTerm``), their cells and settings (``cells``), their history (``history``), what they report
(``measures``) and their columns under the land surface and the stations (``columns``)."""
