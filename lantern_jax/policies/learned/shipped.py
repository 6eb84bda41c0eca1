"""Names and descriptions of the learned models whose checkpoints ship with the package."""

from __future__ import annotations

#: The learned models whose checkpoints ship with the package (``data/models/``; README,
#: "Learned warning-conditioned models"), with their descriptions: the paper's three learned
#: rows, ``learned-coop`` fine-tuned with onset-only horizon exclusion, the
#: distance-conditioned models of the paper's language diagnostics (both exclusion rules), and
#: the closed-loop models (beyond the paper's recipe): front camera, and the six-camera rig.
SHIPPED_MODELS = {
    "learned-base": "language interface trained on ordinary driving, never on warnings "
                    "(the SimLingo analogue)",
    "learned-coop": "learned-base fine-tuned on the LANTERN dataset mixed with base data "
                    "(the Coop-SimLingo analogue)",
    "learned-surround": "six-camera rig, no language (the VAD analogue)",
    "learned-coop-onset-only": "learned-coop, fine-tuned keeping the frames whose horizon "
                               "crosses warning termination (configs/train_coop_onset_only.toml)",
    "learned-distance": "learned-coop's recipe plus far-position counterexamples: Route B frames "
                        "told of a hazard 100 m ahead (configs/train_distance.toml)",
    "learned-distance-onset-only": "learned-distance, fine-tuned keeping the frames whose "
                                   "horizon crosses warning termination "
                                   "(configs/train_distance_onset_only.toml)",
    "learned-closed-loop": "learned-distance-onset-only trained closed loop (DAgger: the expert "
                           "relabels the states the model visits) with counterfactual warnings "
                           "(configs/train_closed_loop.toml)",
    "learned-closed-loop-rig": "the six-camera rig and the warning: nine closed-loop rounds "
                               "with distractor sentences from learned-distance-onset-only-rig "
                               "(configs/train_closed_loop_rig.toml)",
}  # fmt: skip
