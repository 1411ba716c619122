"""Consistency-based diagnosis: the paper's worked examples, rules, priors,
memoisation, a large model, and a brute-force reference on random models."""

from __future__ import annotations

import itertools
import random
import time
from pathlib import Path

import pytest

from validation.diagnosis.model import Observation, Plausibility, SystemModel, load_model
from validation.diagnosis.reiter import Diagnoser, DiagnosisResult, corr_name
from validation.base.errors import ValidationError

M, N = Observation.MATCH, Observation.NO_MATCH
PLAUS, IMPL = Plausibility.PLAUSIBLE, Plausibility.IMPLAUSIBLE
ROOT = Path(__file__).resolve().parents[2]
TELEMAX = ROOT / "configs" / "validation" / "telemax_model.yaml"

G, Y, S = "IMU_GYRO", "IMU_YAW", "SM_YAW"
RELATIONS = {"gyro_yaw": (G, Y), "gyro_sm": (G, S), "yaw_sm": (Y, S)}
# The paper's observations: OBS and OBS'.
OBS = {"gyro_sm": M, "gyro_yaw": N, "yaw_sm": N}
OBS_PRIME = {"gyro_sm": M, "gyro_yaw": M, "yaw_sm": N}


def triangle(masking: str | None = None, **extra) -> SystemModel:
    """IMU_GYRO, IMU_YAW, SM_YAW with relations among all three pairs;
    ``masking``: None, 'no_corr' (a match implies both ok) or 'corr'."""
    rules = []
    if masking is not None:
        rules = [{"relation": r, "corr": masking == "corr"} for r in RELATIONS]
    return SystemModel.model_validate(
        {"components": [G, Y, S], "relations": RELATIONS, "failure_masking": rules, **extra}
    )


def sets(*groups: tuple[str, ...]) -> tuple[frozenset[str], ...]:
    return tuple(frozenset(g) for g in groups)


# --- the paper's worked examples ------------------------------------------


def test_paper_obs_only_imu_yaw_without_failure_masking():
    """OBS: IMU_YAW disagrees with both partners, which agree with each other.
    A match is evidence of health (no failure masking), so IMU_GYRO and SM_YAW
    are ok and {IMU_YAW} is the only minimal diagnosis."""
    result = Diagnoser(triangle("no_corr")).diagnose(OBS)
    assert result.consistent
    assert result.diagnoses == sets((Y,))
    assert result.conflicts == sets((Y,))


def test_paper_obs_in_plain_sd_imu_yaw_is_the_minimum_cardinality_diagnosis():
    """Without the masking rules a match says nothing: the conflicts are
    {IMU_GYRO, IMU_YAW} and {IMU_YAW, SM_YAW}, whose minimal hitting sets are
    {IMU_YAW} and {IMU_GYRO, SM_YAW}; {IMU_YAW} is the only one of least size."""
    result = Diagnoser(triangle()).diagnose(OBS)
    assert set(result.conflicts) == set(sets((G, Y), (Y, S)))
    assert result.diagnoses == sets((Y,), (G, S))
    assert result.minimum_cardinality == sets((Y,))


def test_paper_obs_prime_two_diagnoses():
    """OBS': only IMU_YAW vs SM_YAW disagrees: {IMU_YAW} and {SM_YAW}."""
    result = Diagnoser(triangle()).diagnose(OBS_PRIME)
    assert result.consistent
    assert result.diagnoses == sets((Y,), (S,))
    assert result.conflicts == sets((Y, S))


def test_paper_obs_prime_has_no_diagnosis_with_failure_masking_and_no_corr():
    """Both matches force all three components ok, which contradicts
    no_match(IMU_YAW, SM_YAW) even with every component abnormal."""
    result = Diagnoser(triangle("no_corr")).diagnose(OBS_PRIME)
    assert result.consistent is False
    assert result.diagnoses == ()
    assert result.conflicting_observations == frozenset(OBS_PRIME)


def test_paper_obs_prime_is_explained_with_corr():
    """By hand: the minimal conflicts are {IMU_YAW, SM_YAW},
    {CORR(gyro_yaw), SM_YAW}, {CORR(gyro_sm), IMU_YAW} and
    {CORR(gyro_yaw), CORR(gyro_sm)}. Their minimal hitting sets are
    {IMU_YAW, CORR(gyro_yaw)} and {SM_YAW, CORR(gyro_sm)}: the faulty yaw
    source's match with the gyro was a coincidence. As component sets:
    {IMU_YAW} and {SM_YAW}."""
    result = Diagnoser(triangle("corr")).diagnose(OBS_PRIME)
    assert result.consistent
    assert set(result.conflicts) == {
        frozenset({Y, S}),
        frozenset({corr_name("gyro_yaw"), S}),
        frozenset({corr_name("gyro_sm"), Y}),
        frozenset({corr_name("gyro_yaw"), corr_name("gyro_sm")}),
    }
    assert [(e.components, e.masked) for e in result.explanations] == [
        (frozenset({Y}), frozenset({"gyro_yaw"})),
        (frozenset({S}), frozenset({"gyro_sm"})),
    ]
    assert result.diagnoses == sets((Y,), (S,))


# --- rules, priors, memo --------------------------------------------------


@pytest.mark.parametrize("masking", [None, "no_corr", "corr"])
def test_all_match_gives_only_the_empty_diagnosis(masking):
    result = Diagnoser(triangle(masking)).diagnose({r: M for r in RELATIONS})
    assert result.consistent
    assert result.diagnoses == (frozenset(),)
    assert result.conflicts == ()


def test_fault_propagation_makes_components_appear_together():
    spec = {"components": ["A", "B", "C"], "relations": {"ac": ["A", "C"], "bc": ["B", "C"]}}
    plain = Diagnoser(SystemModel.model_validate(spec)).diagnose({"ac": N})
    assert set(plain.diagnoses) == set(sets(("A",), ("C",)))
    coupled = Diagnoser(SystemModel.model_validate({**spec, "fault_propagation": [["A", "B"]]}))
    assert set(coupled.diagnose({"ac": N}).diagnoses) == set(sets(("A", "B"), ("C",)))
    # B alone observed faulty also drags A along.
    assert set(coupled.diagnose({"bc": N, "ac": M}).diagnoses) == set(sets(("A", "B"), ("C",)))


def test_unary_implausible_blames_its_component():
    model = SystemModel.model_validate(
        {"components": ["A", "B"], "relations": {"ab": ["A", "B"]}, "unary_checks": {"a_ok": "A", "b_ok": "B"}}
    )
    d = Diagnoser(model)
    assert d.diagnose({"ab": M, "a_ok": IMPL, "b_ok": PLAUS}).diagnoses == sets(("A",))
    assert d.diagnose({"ab": M, "a_ok": PLAUS, "b_ok": PLAUS}).diagnoses == (frozenset(),)


def test_unary_implausible_in_shipped_model():
    model = load_model(TELEMAX)
    obs = {r: M for r in model.relations} | {"mag_plausible": IMPL, "gps_plausible": PLAUS}
    result = Diagnoser(model).diagnose(obs)
    assert result.diagnoses == sets(("IMU_YAW",))
    # The shipped model has no failure masking: nothing is retracted but AB.
    assert result.explanations[0].masked == frozenset()


def test_priors_rank_diagnoses_and_give_their_probability():
    d = Diagnoser(triangle(priors={S: 0.2, Y: 0.01, G: 0.05}))
    result = d.diagnose(OBS_PRIME)
    assert result.diagnoses == sets((S,), (Y,))
    assert result.probabilities[0] == pytest.approx(0.2 * 0.99 * 0.95)
    assert result.probabilities[1] == pytest.approx(0.01 * 0.8 * 0.95)
    swapped = Diagnoser(triangle(priors={S: 0.01, Y: 0.2})).diagnose(OBS_PRIME)
    assert swapped.diagnoses == sets((Y,), (S,))


def test_memo_returns_the_same_object_quickly():
    d = Diagnoser(load_model(TELEMAX))
    obs = {"yaw_compass_sm": N, "yaw_gyro_sm": N, "distance_odo_sm": N, "yaw_compass_gyro": M}
    t0 = time.perf_counter()
    first = d.diagnose(obs)
    cold = time.perf_counter() - t0
    t0 = time.perf_counter()
    second = d.diagnose(dict(reversed(list(obs.items()))))
    warm = time.perf_counter() - t0
    assert second is first
    assert d.diagnose(obs | {"gps_plausible": None}) is first  # None: not observed
    assert warm < cold and warm < 1e-3


def test_shipped_model_blames_scan_matching_outdoors():
    """The paper's scenario: every trend observer of scan matching disagrees,
    the rest agree. One fault of the whole scan matcher explains its yaw,
    distance and sideways mismatches."""
    model = load_model(TELEMAX)
    obs = {r: M for r in model.relations} | {"mag_plausible": PLAUS, "gps_plausible": PLAUS}
    for r in ("yaw_compass_sm", "yaw_gyro_sm", "distance_odo_sm", "lateral_odo_sm"):
        obs[r] = N
    result = Diagnoser(model).diagnose(obs)
    assert result.diagnoses[0] == {"SM"}
    # Next, the scan matcher's heading with the odometry's distance, and
    # the three modalities failing independently.
    assert result.diagnoses[1] == {"SM_YAW", "ODO_DIST"}
    assert {"SM_DIST", "SM_LAT", "SM_YAW"} in result.diagnoses
    p = model.prior
    odds = lambda c: p(c) / (1 - p(c))  # noqa: E731
    assert result.probabilities[0] / result.probabilities[1] == pytest.approx(
        odds("SM") / (odds("SM_YAW") * odds("ODO_DIST"))
    )


@pytest.mark.parametrize("observer, modality", [("lateral_odo_sm", "SM_LAT"), ("distance_odo_sm", "SM_DIST")])
def test_shipped_model_prefers_a_scan_matching_modality_for_one_mismatch(observer, modality):
    """Only one translation observer disagrees: odometry or scan matching, and
    the priors make the scan matcher's modality (prone to sliding along a
    lone wall, to sticking in a corridor) the likelier one; the whole
    sensor is less likely than one of its modalities."""
    model = load_model(TELEMAX)
    obs = {r: M for r in model.relations} | {observer: N}
    result = Diagnoser(model).diagnose(obs)
    assert result.diagnoses == sets((modality,), ("SM",), ("ODO_DIST",), ("ODO",))


# --- large models ---------------------------------------------------------


def ring(n: int) -> SystemModel:
    comps = [f"C{i:02d}" for i in range(n)]
    return SystemModel.model_validate(
        {"components": comps, "relations": {f"r{i:02d}": [comps[i], comps[(i + 1) % n]] for i in range(n)}}
    )


@pytest.mark.parametrize("n", [24, 32])
def test_ring_model_all_minimal_diagnoses_fast(n):
    model = ring(n)
    obs = {r: M for r in model.relations} | {"r03": N, "r10": N}
    t0 = time.perf_counter()
    result = Diagnoser(model).diagnose(obs)
    assert time.perf_counter() - t0 < 0.5
    expected = {frozenset({a, b}) for a in ("C03", "C04") for b in ("C10", "C11")}
    assert set(result.diagnoses) == expected and len(result.diagnoses) == 4
    # Two neighbouring disagreements share a component.
    obs |= {"r04": N, "r10": M}
    assert set(Diagnoser(model).diagnose(obs).diagnoses) == set(sets(("C04",), ("C03", "C05")))


def test_ring_model_many_disagreements():
    """Five scattered disagreements: 2**5 minimal diagnoses, still fast."""
    model = ring(24)
    obs = {r: (N if int(r[1:]) % 5 == 0 and int(r[1:]) < 25 else M) for r in model.relations}
    t0 = time.perf_counter()
    result = Diagnoser(model).diagnose(obs)
    assert time.perf_counter() - t0 < 0.5
    assert len(result.diagnoses) == 2**5
    assert all(len(d) == 5 for d in result.diagnoses)


# --- brute-force reference ------------------------------------------------


def brute_force(model: SystemModel, obs: dict) -> tuple[bool, set[tuple[frozenset, frozenset]]]:
    """Minimal diagnoses by enumerating every set of retracted assumables and
    every health assignment, straight from the semantics of SD."""
    comps = list(model.components)
    corrs = [r.relation for r in model.failure_masking if r.corr]
    hard = {r.relation for r in model.failure_masking if not r.corr}

    def consistent(ab: set, masked: set) -> bool:
        for bits in itertools.product([False, True], repeat=len(comps)):
            ok = dict(zip(comps, bits))
            if any(not ok[c] for c in comps if c not in ab):
                continue
            if any(ok[a] != ok[b] for a, b in model.fault_propagation):
                continue
            good = True
            for r, value in obs.items():
                if r in model.unary_checks:
                    good &= not (value is IMPL and ok[model.unary_checks[r]])
                    continue
                a, b = model.relations[r]
                if value is N:
                    good &= not (ok[a] and ok[b])
                elif r in hard or (r in corrs and r not in masked):
                    good &= ok[a] and ok[b]
            if good:
                return True
        return False

    assumables = [("c", c) for c in comps] + [("r", r) for r in corrs]
    found: list[frozenset] = []
    for k in range(len(assumables) + 1):
        for subset in itertools.combinations(assumables, k):
            s = frozenset(subset)
            if any(f <= s for f in found):
                continue
            if consistent({n for t, n in s if t == "c"}, {n for t, n in s if t == "r"}):
                found.append(s)
    as_pairs = {
        (frozenset(n for t, n in s if t == "c"), frozenset(n for t, n in s if t == "r")) for s in found
    }
    return bool(found), as_pairs


def random_model(rng: random.Random) -> SystemModel:
    n = rng.randint(3, 5)
    comps = [f"S{i}" for i in range(n)]
    pairs = [p for p in itertools.combinations(comps, 2) if rng.random() < 0.6] or [tuple(comps[:2])]
    relations = {f"{a}_{b}": [a, b] for a, b in pairs}
    unary = {f"u_{c}": c for c in comps if rng.random() < 0.3}
    prop = [list(rng.sample(comps, 2))] if rng.random() < 0.3 else []
    masking = [
        {"relation": r, "corr": rng.random() < 0.6} for r in list(relations)[:2] if rng.random() < 0.5
    ]
    priors = {c: rng.uniform(0.01, 0.3) for c in comps if rng.random() < 0.5}
    return SystemModel.model_validate(
        {"components": comps, "relations": relations, "unary_checks": unary,
         "fault_propagation": prop, "failure_masking": masking, "priors": priors}
    )


def test_solver_agrees_with_brute_force_on_random_models():
    rng = random.Random(20261121)
    checked = inconsistent = 0
    for _ in range(40):
        model = random_model(rng)
        d = Diagnoser(model)
        for _ in range(8):
            obs = {}
            for r in model.relations:
                if rng.random() < 0.85:
                    obs[r] = rng.choice([M, N])
            for u in model.unary_checks:
                if rng.random() < 0.7:
                    obs[u] = rng.choice([PLAUS, IMPL, PLAUS])
            result: DiagnosisResult = d.diagnose(obs)
            ok, expected = brute_force(model, obs)
            assert result.consistent == ok, (model, obs)
            got = {(e.components, e.masked) for e in result.explanations}
            assert got == expected, (model, obs)
            assert len(result.explanations) == len(expected)
            assert list(result.probabilities) == sorted(result.probabilities, reverse=True)
            checked += 1
            inconsistent += not ok
    assert checked == 320 and inconsistent > 0


# --- model errors ---------------------------------------------------------


def test_model_errors_name_the_key(tmp_path):
    bad = tmp_path / "m.yaml"
    bad.write_text("components: [A, B]\nrelations:\n  ab: [A, C]\n")
    with pytest.raises(ValidationError, match=r"m\.yaml: relations\.ab: unknown component 'C'"):
        load_model(bad)
    bad.write_text("components: [A, B]\nrelashuns: {}\n")
    with pytest.raises(ValidationError, match="unknown key 'relashuns'"):
        load_model(bad)
    bad.write_text("components: [A, B]\npriors: {A: 1.5}\n")
    with pytest.raises(ValidationError, match="priors: prior of 'A' must be in"):
        load_model(bad)
    bad.write_text("components: [A, B]\nfailure_masking:\n  - {relation: ab}\n")
    with pytest.raises(ValidationError, match="failure_masking.0: unknown relation 'ab'"):
        load_model(bad)
    with pytest.raises(ValidationError, match="cannot read"):
        load_model(tmp_path / "missing.yaml")


def test_unknown_observation_is_an_error():
    d = Diagnoser(triangle())
    with pytest.raises(ValidationError, match="'gyro_gps': not a relation"):
        d.diagnose({"gyro_gps": M})
    with pytest.raises(ValidationError, match="unexpected value"):
        d.diagnose({"gyro_sm": PLAUS})


def _ceiling_model(false_alarm: float | None) -> SystemModel:
    return SystemModel(
        components=("ODO_DIST", "SM_DIST", "SM_YAW", "SM"), sensors={"SM": ("SM_DIST", "SM_YAW")},
        relations={"distance_odo_sm": ("ODO_DIST", "SM_DIST")}, unary_checks={"scan_ceiling": "SM"},
        false_alarm={"scan_ceiling": false_alarm} if false_alarm else {},
        priors={"ODO_DIST": 0.05, "SM_DIST": 0.02, "SM": 0.02},
    )


def test_a_check_that_may_raise_false_alarms_is_weighed_not_obeyed():
    """Alone, an implausible verdict of a check that errs one time in ten is
    more probably a false alarm than a fault (prior 0.02); beside a mismatch
    of the odometry with scan matching it turns the blame from the odometry
    (more probable by its prior) to the scan matcher the check tests."""
    cut = {"scan_ceiling": Plausibility.IMPLAUSIBLE}
    mismatch = {"distance_odo_sm": Observation.NO_MATCH}
    with Diagnoser(_ceiling_model(0.1)) as d:
        alone = d.diagnose(cut)
        assert alone.diagnoses[0] == frozenset() and frozenset({"SM"}) in alone.diagnoses
        assert alone.explanations[0].dismissed == {"scan_ceiling"}
        assert d.diagnose(mismatch).diagnoses[0] == {"ODO_DIST"}
        assert d.diagnose({**mismatch, **cut}).diagnoses[0] == {"SM"}
    with Diagnoser(_ceiling_model(None)) as d:
        assert d.diagnose(cut).diagnoses == (frozenset({"SM"}),)  # a hard check decides alone


def test_a_relation_that_may_raise_false_alarms_blames_only_with_other_evidence():
    """A mismatch that happens one step in ten between healthy sensors is,
    alone, a false alarm; two such relations mismatching on one sensor are
    more probably its fault (0.02) than two coincidences (0.01)."""
    model = SystemModel(
        components=("ODO_DIST", "ODO_YAW", "SM_DIST", "SM_YAW", "SM"), sensors={"SM": ("SM_DIST", "SM_YAW")},
        relations={"distance_odo_sm": ("ODO_DIST", "SM_DIST"), "yaw_odo_sm": ("ODO_YAW", "SM_YAW")},
        false_alarm={"distance_odo_sm": 0.1, "yaw_odo_sm": 0.1},
        priors={"ODO_DIST": 0.02, "ODO_YAW": 0.02, "SM_DIST": 0.05, "SM_YAW": 0.05, "SM": 0.02},
    )
    with Diagnoser(model) as d:
        one = d.diagnose({"distance_odo_sm": Observation.NO_MATCH, "yaw_odo_sm": Observation.MATCH})
        assert one.diagnoses[0] == frozenset() and one.explanations[0].dismissed == {"distance_odo_sm"}
        both = d.diagnose({"distance_odo_sm": Observation.NO_MATCH, "yaw_odo_sm": Observation.NO_MATCH})
        assert both.diagnoses[0] == {"SM"}


def test_only_an_observer_may_raise_false_alarms():
    with pytest.raises(ValueError, match="'A'.*not a relation or unary check"):
        SystemModel(components=("A", "B"), relations={"distance_odo_sm": ("A", "B")}, false_alarm={"A": 0.1})
