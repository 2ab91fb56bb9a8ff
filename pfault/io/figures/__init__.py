"""The former place of pfault.post.figures, kept for its command: ``python -m pfault.io.figures RUN_DIR`` (README gave
it before post-processing had its own package) runs ``python -m pfault.post.figures`` (__main__.py)."""
