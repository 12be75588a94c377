"""The paper's experiments, reproducible by one call each: figures (:mod:`~gnipy.experiments.figures`)."""
