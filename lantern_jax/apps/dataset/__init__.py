"""The open-loop dataset: expert rollouts on fresh scenes, recorded at 4 Hz for training.

* :mod:`~lantern_jax.apps.dataset.scenes` — fresh Route A / Route B scenes of every family and
  weather, disjoint from the frozen suite, with the open-loop (geometric) event trigger;
* :mod:`~lantern_jax.apps.dataset.record` — batched expert rollouts that keep every fifth 20 Hz tick
  (4 Hz): the policy observation of that tick (front camera: visible objects and a semantic
  range image), the six-camera rig's view, and the ego pose;
* :mod:`~lantern_jax.apps.dataset.frames` — per sequence: the ten future expert waypoints of each
  frame in its ego frame, horizon-crossing flags, the event timeline and the paper's open-loop
  acceptance rules;
* :mod:`~lantern_jax.apps.dataset.store` — sharded Parquet files written atomically shard by shard
  (an interrupted run resumes), a dataset card, validation that names the file, and a seeded,
  shuffled, batched loader.
"""
