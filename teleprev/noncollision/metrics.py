"""Figures of a CPN on labelled configurations: per-link ROC AUC, recall and the operating threshold."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def roc_auc(scores: np.ndarray, labels: np.ndarray) -> float:
    """Area under the ROC curve (Mann-Whitney U with ties counted half); nan if one class is absent."""
    labels = np.asarray(labels, dtype=bool)
    n_pos, n_neg = int(labels.sum()), int((~labels).sum())
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    order = np.argsort(scores, kind="mergesort")
    s = np.asarray(scores)[order]
    ranks = np.empty(len(s))
    # average ranks over ties
    starts = np.flatnonzero(np.r_[True, s[1:] != s[:-1]])
    ends = np.r_[starts[1:], len(s)]
    avg = 0.5 * (starts + ends - 1) + 1.0
    ranks[order] = np.repeat(avg, ends - starts)
    return float((ranks[labels].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


@dataclass(frozen=True)
class CPNFigures:
    auc_per_link: np.ndarray
    auc_min_link: float
    recall: float  # colliding link labels predicted colliding
    precision: float
    config_fnr: float  # colliding configurations predicted entirely free
    config_fpr: float  # free configurations predicted colliding somewhere
    n: int

    def as_dict(self, prefix: str = "cpn_") -> dict:
        return {
            f"{prefix}auc_min_link": self.auc_min_link,
            f"{prefix}recall": self.recall,
            f"{prefix}precision": self.precision,
            f"{prefix}config_fnr": self.config_fnr,
            f"{prefix}config_fpr": self.config_fpr,
        }


def cpn_figures(prob: np.ndarray, labels: np.ndarray, threshold: float) -> CPNFigures:
    labels = np.asarray(labels, dtype=bool)
    pred = prob >= threshold
    aucs = np.array([roc_auc(prob[:, i], labels[:, i]) for i in range(labels.shape[1])])
    colliding = labels.any(axis=1)
    flagged = pred.any(axis=1)
    return CPNFigures(
        auc_per_link=aucs,
        auc_min_link=float(np.nanmin(aucs)),
        recall=float(pred[labels].mean()) if labels.any() else float("nan"),
        precision=float(labels[pred].mean()) if pred.any() else float("nan"),
        config_fnr=float((~flagged[colliding]).mean()) if colliding.any() else float("nan"),
        config_fpr=float(flagged[~colliding].mean()) if (~colliding).any() else float("nan"),
        n=len(labels),
    )


def recall_threshold(prob: np.ndarray, labels: np.ndarray, recall: float, config_fnr: float) -> float:
    """The largest threshold at which at least `recall` of the colliding link labels are predicted colliding
    and at most `config_fnr` of the colliding configurations are predicted entirely free."""
    labels = np.asarray(labels, dtype=bool)
    t_label = np.quantile(prob[labels], 1.0 - recall, method="lower") if labels.any() else 1.0
    colliding = labels.any(axis=1)
    t_cfg = np.quantile(prob[colliding].max(axis=1), config_fnr, method="lower") if colliding.any() else 1.0
    return float(np.clip(min(t_label, t_cfg), 1e-6, 0.5))
