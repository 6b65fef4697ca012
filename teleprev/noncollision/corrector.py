"""The runtime Corrector: whatever comes in, a collision-free configuration within the limits goes out.

    input free (exact check)            -> the input, untouched
    else the CCN proposes p; the smallest fraction of the correction (in quarters) that the CPN predicts
    free is checked exactly; if it collides, p itself is
                                        -> the first of those that is free                action "ccn"
    else                                -> fallback                                       action "fallback"
        1. the CCN's correction, lengthened up to twice: the first point the CPN predicts free, checked
           exactly (the direction is usually right and the step a little short)
        2. a few gradient-projection steps on the CPN from the proposal, then one exact check
        3. points on the segment from the proposal to a safe anchor (the previous output if it is
           free, else the open hand), nearest the proposal first, those the CPN predicts free; each
           checked exactly, at most `segment_checks` of them
        4. the anchor itself, which is collision-free

Taking as little of the CCN's correction as the checker allows keeps the output next to the input where
the input only just collides, so a smooth input trajectory entering or leaving collision gives a smooth
output (the full proposal would jump by the CCN's safety margin), and it lowers the deviation.
Every answer has passed the exact checker (the anchor was checked when it became the anchor), so no
path returns a colliding configuration. No torch: this runs in every pipeline step. The CPN / CCN
inference runs in numba kernels (noncollision/compiled.py), the CCN step (proposal and bisection) in one
call; older sessions corrected with the numpy networks re-run with
teleprev.pipeline.older_formats.NumpyCorrector.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleprev.errors import ModelError
from teleprev.kernels import correction as correction_kernels
from teleprev.noncollision.mlp import CCN, CPN, file_sha256, load_model
from teleprev.noncollision.projection import ProjectionSettings, descend
from teleprev.robot.collision import SelfCollisionChecker
from teleprev.robot.collision_report import CollisionReport
from teleprev.robot.model import RobotModel

ACTIONS = ("untouched", "ccn", "fallback")


@dataclass(frozen=True)
class Correction:
    q: np.ndarray  # collision-free (exact check) and within limits, always
    action: str  # "untouched" | "ccn" | "fallback"
    colliding_links: tuple[str, ...]  # links that collided in the input (empty if untouched)
    deviation: float  # max |q_out - q_in| in rad


@dataclass(frozen=True)
class Prepared:
    """An input with the state-independent part of its correction done (Corrector.prepare)."""

    q: np.ndarray  # the input
    q0: np.ndarray  # clipped to the limits
    report: CollisionReport  # the exact check of q0
    proposal: np.ndarray | None = None  # the CCN's proposal for q0 (batches only, where q0 collides)
    answer: Correction | None = None  # the correction, where it needs no previous output (batches only)


@dataclass(frozen=True)
class CorrectorSettings:
    shorten_levels: int = 2  # CPN bisection levels along the correction (0: always the full CCN proposal)
    projection_steps: int = 8
    segment_points: int = 16
    segment_checks: int = 3
    projection: ProjectionSettings = ProjectionSettings()


def find_models(models_dir: Path, model: RobotModel) -> tuple[Path, Path]:
    """The CPN and CCN files in `models_dir` made for this robot (by the `robot` name in their metadata)."""
    from safetensors import safe_open

    models_dir = Path(models_dir)
    if not models_dir.is_dir():
        raise ModelError("no such models folder", str(models_dir))
    found: dict[str, list[Path]] = {"cpn": [], "ccn": []}
    others = []
    for path in sorted(models_dir.glob("c[cp]n_*.safetensors")):
        kind = path.name[:3]
        try:
            with safe_open(str(path), framework="numpy") as f:
                robot = (f.metadata() or {}).get("robot")
        except Exception:
            robot = None  # unreadable: load_model below says why, if it is the one we need
            found[kind].append(path)
            continue
        (found[kind] if robot == model.name else others).append(path)
    for kind in ("cpn", "ccn"):
        if not found[kind]:
            seen = f" (found only {', '.join(p.name for p in others)})" if others else ""
            raise ModelError(
                f"no {kind.upper()} for robot {model.name!r}{seen}; train one with `teleprev collision train-{kind}`",
                str(models_dir),
            )
        if len(found[kind]) > 1:
            raise ModelError(
                f"several {kind.upper()} files for robot {model.name!r}: {', '.join(p.name for p in found[kind])}; "
                "keep one",
                str(models_dir),
            )
    return found["cpn"][0], found["ccn"][0]


class Corrector:
    def __init__(self, model: RobotModel, checker: SelfCollisionChecker, cpn: CPN, ccn: CCN,
                 settings: CorrectorSettings = CorrectorSettings(), files: dict[str, Path] | None = None):
        self.model = model
        self.checker = checker
        self.cpn = cpn
        self.ccn = ccn
        self.settings = settings
        self.files = dict(files or {})  # the weight files by role ("cpn", "ccn"), when loaded from files
        self.neutral = model.neutral()
        if checker.collides(self.neutral):
            raise ModelError(
                "the neutral (open) hand is in self-collision, so there is no safe fallback pose", str(model.urdf_path)
            )
        s = np.linspace(0.0, 1.0, settings.segment_points + 1)[1:]
        self._segment = s[:, None]
        self._extend = np.linspace(1.0, 2.0, 9)[1:, None]
        self._load_networks()

    def _load_networks(self) -> None:
        """The kernels' CPN, CCN and fused CCN step (noncollision/compiled.py), loaded from numba's cache now,
        not in a live loop's first steps; `_cpn` is what the fallback asks (the compiled CPN, whose gradient
        is the numpy one's)."""
        from teleprev.noncollision.compiled import CompiledNets

        self._nets = CompiledNets(self.cpn, self.ccn, self.settings.shorten_levels)
        self._cpn = self._nets.cpn
        self._nets.propose_shorten(self.neutral[None])
        tables = getattr(self.checker, "kernel_tables", None)  # FCL's checker has none
        # correct_one's tables after the configuration (None: the checker has no compiled check)
        self._one = None if tables is None else (*tables[0], *tables[1], *tables[2], *self._nets.step)
        if self._one is not None:
            self._prepare_one(self.neutral, self.neutral)
        self._cpn.predicts_free(self.neutral[None])

    @classmethod
    def load(cls, models_dir: Path | None, model: RobotModel, checker: SelfCollisionChecker | None = None) -> Corrector:
        """The CPN and CCN for `model` from `models_dir` (None: the shipped models/ folder)."""
        from teleprev.paths import data_dir

        checker = checker if checker is not None else SelfCollisionChecker(model)
        cpn_path, ccn_path = find_models(Path(models_dir) if models_dir is not None else data_dir("models"), model)
        cpn = CPN(load_model(cpn_path, "cpn", model, checker.link_names))
        ccn_net = load_model(ccn_path, "ccn", model)
        trained_with = (ccn_net.info.training or {}).get("cpn", {}).get("sha256")
        if trained_with is not None and trained_with != file_sha256(cpn_path):
            raise ModelError(
                f"trained against another CPN than {cpn_path.name}; retrain the CCN (`teleprev collision train-ccn`)",
                str(ccn_path),
            )
        return cls(
            model, checker, cpn, CCN(ccn_net, model.lower, model.upper), files={"cpn": cpn_path, "ccn": ccn_path}
        )

    def model_hashes(self) -> dict[str, str]:
        """{role: sha256} of the weight files loaded (a session records them, eval compares them)."""
        return {role: file_sha256(path) for role, path in self.files.items()}

    # ---- the pipeline's call ----------------------------------------------------------------------
    def prepare(self, q: np.ndarray) -> list[Prepared]:
        """The part of `correct` that depends on the input alone, for inputs (N, n): each clipped to the
        limits and checked exactly, and for a batch also the correction itself unless it falls back (that
        needs the previous output). The same answers as `correct` alone: the batch check answers as the
        single one, and a row's arithmetic in the kernels does not depend on its batch."""
        q_in = np.asarray(q, dtype=float)
        if q_in.ndim != 2 or q_in.shape[1:] != self.model.lower.shape or not np.isfinite(q_in).all():
            raise ValueError(f"expected rows of {len(self.model.lower)} finite joint values, got "
                             f"{np.array2string(q_in, precision=3)}")
        q0 = self.model.clip(q_in)
        if len(q0) == 1:
            return [self._prepare_one(q_in[0], q0[0])]
        return self._prepare_batch(q_in, q0, self.checker.pair_matrix(q0))

    def _prepare_one(self, q_in: np.ndarray, q0: np.ndarray) -> Prepared:
        """prepare's one configuration (the live step's case), with its answer where no FCL and no previous
        output is needed: the exact check, the CCN step and the exact checks of its proposals in one kernel
        call (teleprev/kernels/correction.py), the same checks in the same order as `correct`."""
        if self._one is None:
            return Prepared(q_in, q0, self.checker.check(q0))
        labels = np.zeros(len(self.checker.link_names), dtype=bool)
        index = np.empty(len(self.checker.link_pairs), dtype=np.int64)
        out = np.empty_like(q0)
        q_in, q0 = np.ascontiguousarray(q_in), np.ascontiguousarray(q0)  # the kernel's types: no compile in a step
        answer, count, deviation = correction_kernels.correct_one(q_in, q0, *self._one, labels, index, out)
        report = self.checker.report_of(count, labels, index)  # the exact check's, as checker.check gives it
        if report is None:  # q0 within the margin of touching: FCL decides
            return Prepared(q_in, q0, self.checker.check(q0))
        if answer == correction_kernels.ONE_UNDECIDED:  # a proposal for FCL, or both collide: `correct` decides
            return Prepared(q_in, q0, report)
        if answer == correction_kernels.ONE_UNTOUCHED:
            return Prepared(q_in, q0, report, None, Correction(out, "untouched", (), deviation))
        links = tuple(report.colliding_links(self.checker.link_names))
        return Prepared(q_in, q0, report, None, Correction(out, "ccn", links, deviation))

    def _prepare_batch(self, q_in: np.ndarray, q0: np.ndarray, pairs: np.ndarray) -> list[Prepared]:
        """prepare's batch (the kernels answer a row as alone): every answer that needs no
        previous output, computed for the whole batch at once. The CCN step runs for all colliding rows
        in one kernel call; the shortened proposals are checked exactly in one batched pass, the full
        proposals only for the rows whose shortened one collides (or was not found); deviations in one
        array operation. Each (report, colliding links) is built once per distinct set of colliding pairs
        (a session holds few; the free rows share one), and shared, read-only, by the rows that have it. The same
        checks in the same
        order as _ccn_answer row by row: the same answers."""
        n_rows = len(q0)
        untouched = np.abs(q0 - q_in).max(axis=1).tolist()
        hit = pairs.any(axis=1)
        reports, links = [None] * n_rows, [()] * n_rows
        seen: dict[bytes, tuple[CollisionReport, tuple[str, ...]]] = {}
        names, link_names = self.checker.link_pairs, self.checker.link_names
        rows = np.flatnonzero(hit)
        for i in range(n_rows):  # a free row's pairs are all zero: one more key
            key = pairs[i].tobytes()
            known = seen.get(key)
            if known is None:
                label = self.checker.labels_from_pairs(pairs[i:i + 1])[0]
                label.setflags(write=False)
                report = CollisionReport(label, tuple(names[k] for k in np.flatnonzero(pairs[i])))
                known = seen[key] = (report, tuple(report.colliding_links(link_names)))
            reports[i], links[i] = known
        out = [
            None
            if collides
            else Prepared(q_in[i], q0[i], reports[i], None, Correction(q0[i], "untouched", (), untouched[i]))
            for i, collides in enumerate(hit.tolist())
        ]
        if not len(rows):
            return out
        proposals, shortened, his = self._nets.propose_shorten(q0[rows])
        # _ccn_answer for every row: the shortened proposal where the CPN found one and it is free, else the
        # full proposal where it is free, else none (the fallback, which needs the previous output)
        short = his != self._nets.steps
        chosen = np.full(len(rows), -1)  # 0: the shortened proposal, 1: the full one, -1: neither
        k_short = np.flatnonzero(short)
        chosen[k_short[~self._collides_rows(shortened[k_short])]] = 0
        k_full = np.flatnonzero(chosen < 0)
        chosen[k_full[~self._collides_rows(proposals[k_full])]] = 1
        answer_q = np.where((chosen == 0)[:, None], shortened, proposals)
        deviation = np.abs(answer_q - q_in[rows]).max(axis=1).tolist()
        for k, (i, c) in enumerate(zip(rows.tolist(), chosen.tolist())):
            answer = None if c < 0 else Correction(answer_q[k], "ccn", links[i], deviation[k])
            out[i] = Prepared(q_in[i], q0[i], reports[i], proposals[k], answer)
        return out

    def _collides_rows(self, q: np.ndarray) -> np.ndarray:
        """(N,) bool: checker.collides of each configuration of q (N, n), the free rows in one compiled pass
        (first_collision answers as collides does, row by row)."""
        out = np.zeros(len(q), dtype=bool)
        start = 0
        while start < len(q):
            k = self.checker.first_collision(q[start:])
            if k is None:
                break
            out[start + k] = True
            start += k + 1
        return out

    def correct(
        self, q: np.ndarray, previous: np.ndarray | None = None, prepared: Prepared | None = None
    ) -> Correction:
        """`prepared`: `prepare`'s answer for q, when computed ahead."""
        if prepared is None:
            prepared = self.prepare(np.asarray(q, dtype=float)[None])[0]
        if prepared.answer is not None:
            return prepared.answer
        q_in, q0, report = prepared.q, prepared.q0, prepared.report
        if not report.colliding:
            return Correction(q0, "untouched", (), float(np.abs(q0 - q_in).max()))
        proposal = prepared.proposal
        if proposal is None:
            proposal, shorter = self._propose(q0)
            answer = self._ccn_answer(q_in, shorter, proposal, report)
            if answer is not None:
                return answer
        out = self._fallback(q0, proposal, previous)
        links = tuple(report.colliding_links(self.checker.link_names))
        return Correction(out, "fallback", links, float(np.abs(out - q_in).max()))

    def _ccn_answer(self, q_in: np.ndarray, shorter: np.ndarray | None, proposal: np.ndarray,
                    report: CollisionReport) -> Correction | None:
        """The shortened correction if it is free, else the full proposal if it is, else None (fallback)."""
        links = tuple(report.colliding_links(self.checker.link_names))
        if shorter is not None and not self.checker.collides(shorter):
            return Correction(shorter, "ccn", links, float(np.abs(shorter - q_in).max()))
        if not self.checker.collides(proposal):
            return Correction(proposal, "ccn", links, float(np.abs(proposal - q_in).max()))
        return None

    def _propose(self, q0: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The CCN's proposal for q0, and the smallest fraction k / 2**shorten_levels of its correction the
        CPN predicts free (None: only the full one), in one kernel call."""
        proposals, shortened, his = self._nets.propose_shorten(q0[None])
        return proposals[0], None if his[0] == self._nets.steps else shortened[0]

    # ---- fallback -------------------------------------------------------------------------------
    def _anchor(self, previous: np.ndarray | None) -> np.ndarray:
        if previous is not None:
            prev = np.asarray(previous, dtype=float)
            if (prev.shape == self.neutral.shape and np.all(np.isfinite(prev)) and self.model.within_limits(prev)
                    and not self.checker.collides(prev)):
                return prev
        return self.neutral

    def _fallback(self, q0: np.ndarray, proposal: np.ndarray, previous: np.ndarray | None) -> np.ndarray:
        s = self.settings
        longer = self.model.clip(q0 + self._extend * (proposal - q0))
        free = np.flatnonzero(self._cpn.predicts_free(longer))
        if len(free) and not self.checker.collides(longer[free[0]]):
            return longer[free[0]]
        q = proposal
        for _ in range(s.projection_steps):
            q, free = descend(self._cpn, self.model, q, q0, s.projection)
            if free:
                break
        if not self.checker.collides(q):
            return q
        anchor = self._anchor(previous)
        points = proposal + self._segment * (anchor - proposal)
        candidates = np.flatnonzero(self._cpn.predicts_free(points[:-1]))
        for k in candidates[: s.segment_checks]:
            if not self.checker.collides(points[k]):
                return points[k]
        return anchor
