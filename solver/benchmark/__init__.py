"""The seed paper's benchmark: estimating dynamics from motion (Werling et al. 2024, §5).

Modules
-------
dataset
    Inputs (coordinates q̃ of the scaled model) and ground truth (centre-of-mass
    acceleration, per-foot GRF and GRM at the foot origin, joint torques) per frame from
    processed subjects; frame selection; splits by subject.
metrics
    The four metrics (CoM acceleration, GRM, GRF, joint torque errors), per kg.
analytical
    The analytical baseline (central differences, F = m a split over the feet, ID).
mlp
    The MLP baseline (PyTorch, optional extra ``mlp``) and the shared network training.
hybrid
    Not in the paper: the analytical total force split between the feet by a network.
evaluate
    Scoring a method on the benchmark frames.
filtering
    The filtering study: analytical baseline error against the low-pass cut-off.
report
    The paper's table layout (JSON, Markdown) and the dataset summary.
run
    Running methods over splits (used by ``addb benchmark``).
"""
