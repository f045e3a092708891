"""Plumbing the stages share: the Hydra command line (``cli``: config composition, the stage
wrapper, running a stage by name, imports whose errors name the fix), a stage's artifacts as its
config names them (``stage_artifacts``: the upstream folders its version keys ask for, its own
version and run) and the executor that spreads a stage's shards over processes or a Ray
cluster (``executor``). Nothing here changes
a stage's numbers, so it is left out of the artifacts' source hashes.
"""
