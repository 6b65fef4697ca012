"""Non-collision module (appendix A of the TelePreview paper): map self-colliding hand configurations to
nearby collision-free ones.

    sampling.py      uniform and collision-boundary samples, labelled by the exact checker
    dataset.py       parallel, resumable generation into parquet shards
    groups.py        which joints can collide with which (the CPN's structure)
    mlp.py           numpy MLPs (CPN, CCN) and their safetensors files
    torch_util.py    the same networks in torch, for training only
    train_cpn.py     Self-Collision Prediction Network training
    train_ccn.py     Invalid Configuration Correction Network training
    grid_search.py   the alpha/beta grid for the CCN loss
    metrics.py       ROC AUC, recall, the operating threshold
    evaluate.py      held-out figures on freshly generated data
    cards.py         the model cards written beside the models
    projection.py    baseline: gradient projection on the frozen CPN (numpy)
    trajectories.py  retargeted human hand trajectories (open, fist, pinch, spread, crossed)
    corrector.py     the runtime Corrector the pipeline calls (numpy only)
"""
