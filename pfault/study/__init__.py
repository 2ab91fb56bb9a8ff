"""Studies built on finished runs: figures of a run directory (``figures``) and the two case studies of
Franceschini et al. (Proc. IAHS 372, 2015) against the paper (``casestudies``)."""
