"""``python -m pfault.io.figures RUN_DIR [RUN_DIR ...] [--step K]``: ``python -m pfault.post.figures``."""

from pfault.post.figures import main

raise SystemExit(main())
