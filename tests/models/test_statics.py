"""Statics (Sec. III, Algorithm 1) checked three independent ways.

1. Free bodies (the paper's Steps 1-3) with the tendons as explicit force lines between their
   tangent points, so the moment arms come from geometry, not from the R_k in the solver.
2. The serial model's equilibrium is the minimum of the potential energy (utrf.models.energy:
   rigid transforms, complex-step gradient, scipy BFGS). Stated tolerance: tip within 1e-8 m,
   tensions within 1e-6 relative (plus 1e-6 N), over random geometries and loads.
3. The printed model's fixed point, found by scipy's root finder on the configuration equation
   with the loads' moments from the energy module.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import root

from utrf.models import energy, kinematics, statics, statics_passes, tendons
from utrf.models.geometry import FingerGeometry
from utrf.models.statics import Load, StaticsError

from .conftest import cases, geometries, moderate_force, unit
from .tendon_geometry import rotate, tangent_points

G = statics.GRAVITY_MPS2


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _tendon_forces(
    g: FingerGeometry, theta: np.ndarray, net: np.ndarray
) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """Force lines (point, force) each tendon puts on each link, from the explicit geometry."""
    L, R = g.link_lengths_m, g.guide_radii_m
    phi = np.cumsum(theta)
    j2 = L[0] * unit(phi[0])
    j3 = j2 + L[1] * unit(phi[1])
    on: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {"link1": [], "link2": [], "link3": []}
    # Tendon 1 / 4 leaves Link 1's R1 guide along −x toward its motor, from the top (flexion)
    # or the bottom (extension) of the guide.
    t1 = abs(net[0])
    side = 1.0 if net[0] >= 0 else -1.0
    on["link1"].append((np.array([0.0, side * R[0]]), np.array([-t1, 0.0])))
    # Crossed strands: tangent points in the spanning link's frame, then to the world.
    for level, (ra, rb, d, origin, angle, distal) in enumerate(
        [(R[0], R[1], L[0], np.zeros(2), phi[0], "link2"), (R[1], R[2], L[1], j2, phi[1], "link3")]
    ):
        n = net[level + 1]
        p_a, p_b = tangent_points(ra, rb, d, "flexion" if n >= 0 else "extension")
        wa, wb = origin + rotate(p_a, angle), origin + rotate(p_b, angle)
        pull = abs(n) * (wa - wb) / np.hypot(*(wa - wb))
        on[distal].append((wb, pull))
        if level == 1:  # Tendon 3 / 6 is anchored on Link 1 at its proximal end
            on["link1"].append((wa, -pull))
    del j3
    return on


def _load_forces(g: FingerGeometry, theta: np.ndarray, load: Load) -> dict[str, list]:
    pts = kinematics.chain_positions(g, theta)
    phi3 = theta.sum()
    f = np.array(load.tip_force_n) + np.array([0.0, -load.payload_kg * G])
    f = f - load.grasp_force_n * np.array([-math.sin(phi3), math.cos(phi3)])
    on: dict[str, list] = {"link1": [], "link2": [], "link3": [(pts[3], f)]}
    if load.gravity:
        for j, name in enumerate(("link1", "link2", "link3")):
            com = pts[j] + g.link_com_fraction[j] * (pts[j + 1] - pts[j])
            on[name].append((com, np.array([0.0, -g.link_masses_kg[j] * G])))
    return on


def _residual_moments(
    g: FingerGeometry, theta: np.ndarray, net: np.ndarray, load: Load
) -> np.ndarray:
    """Moment about Joint k of everything acting on Links k..3 from outside them."""
    pts = kinematics.chain_positions(g, theta)
    tf, lf = _tendon_forces(g, theta, net), _load_forces(g, theta, load)
    links = ("link1", "link2", "link3")
    out = np.zeros(3)
    for k in range(3):
        body = links[k:]
        total = load.tip_moment_nm
        for name in body:
            for p, f in lf[name] + tf[name]:
                total += _cross(p - pts[k], f)
        out[k] = total
    # Tendon 3 / 6 joins Link 1 and Link 3: internal to the body of Step 3 (k = 0), where its two
    # force lines are equal and opposite on one line and so cancel by themselves.
    return out


@settings(max_examples=60, deadline=None)
@given(c=cases(), grasp=st.floats(0.0, 1.0), model=st.sampled_from(statics.MODELS))
def test_free_bodies_balance_with_geometric_tendon_lines(c, grasp: float, model: str) -> None:
    g, q, kw = c
    load = Load(grasp_force_n=grasp * moderate_force(g), **kw)  # type: ignore[arg-type]
    res = statics.solve(g, q, load, model=model, threshold_m=1e-12)
    assert res.converged
    # The tensions balance the loads at the configuration they were computed for.
    tau = statics.generalised_forces(
        g,
        res.theta_rad,
        tip_force_n=np.array(load.tip_force_n),
        tip_moment_nm=load.tip_moment_nm,
        grasp_force_n=load.grasp_force_n,
        gravity=load.gravity,
    )
    net = statics.net_tensions(g, tau)
    scale = 1.0 + np.abs(net).max() * max(g.guide_radii_m)
    np.testing.assert_allclose(
        _residual_moments(g, res.theta_rad, net, load), 0.0, atol=1e-10 * scale
    )
    np.testing.assert_allclose(net, res.net_tensions_n, rtol=1e-6, atol=1e-6)


@settings(max_examples=60, deadline=None)
@given(c=cases())
def test_generalised_forces_equal_minus_the_load_potential_gradient(c) -> None:
    g, q, kw = c
    load = Load(payload_kg=0.3, **kw)  # type: ignore[arg-type]
    theta = kinematics.joint_angles(g, q) + np.array([0.1, -0.2, 0.3])
    tau = statics.generalised_forces(
        g,
        theta,
        tip_force_n=np.add(kw["tip_force_n"], [0.0, -0.3 * G]),
        tip_moment_nm=kw["tip_moment_nm"],
        gravity=kw["gravity"],
    )
    np.testing.assert_allclose(tau, energy.load_torques(g, load, theta), rtol=1e-10, atol=1e-12)


@settings(max_examples=80, deadline=None)
@given(c=cases(), payload=st.floats(0.0, 1.0))
def test_serial_model_agrees_with_the_energy_minimum(c, payload: float) -> None:
    g, q, kw = c
    load = Load(payload_kg=payload * moderate_force(g) / G, **kw)  # type: ignore[arg-type]
    res = statics.solve(g, q, load, model="serial", threshold_m=1e-12)
    sol = energy.solve_energy(g, q, load)
    assert res.converged
    np.testing.assert_allclose(res.tip_m, sol.tip, atol=1e-8)
    np.testing.assert_allclose(
        res.net_tensions_n,
        sol.net_tensions_n,
        rtol=1e-6,
        atol=1e-6 + 1e-6 * np.abs(sol.net_tensions_n).max(),
    )


@settings(max_examples=40, deadline=None)
@given(c=cases(rotation_rad=0.45), relaxation=st.sampled_from(statics.RELAXATIONS))
def test_heavy_loads_converge_to_the_energy_minimum(c, relaxation: str) -> None:
    """Three times the stretch of the other cases: the plain iteration may crawl, so it gets
    more passes; "auto" and "aitken" reach the same equilibrium within the default 100."""
    g, q, kw = c
    load = Load(**kw)  # type: ignore[arg-type]
    passes = 1000 if relaxation == "none" else statics.DEFAULT_MAX_ITERATIONS
    res = statics.solve(g, q, load, threshold_m=1e-12, relaxation=relaxation, max_iterations=passes)
    sol = energy.solve_energy(g, q, load)
    assert res.converged
    np.testing.assert_allclose(res.tip_m, sol.tip, atol=1e-8)


def test_auto_relaxation_rescues_an_oscillating_iteration() -> None:
    # A soft, thin-tendoned finger with small guides and heavy distal links: under its own
    # weight the plain iteration overshoots and oscillates with a ratio near -0.8 per pass.
    g = FingerGeometry(
        link_lengths_m=(0.0625, 0.0625, 0.0625),
        guide_radii_m=(0.002, 0.002, 0.0078125),
        tendon_diameter_m=0.0005,
        tendon_youngs_modulus_pa=50e9,
        actuating_tendon_length_m=0.25,
        link_masses_kg=(0.0, 0.03125, 0.046875),
        link_com_fraction=(0.0, 0.0, 0.0),
    )
    plain = statics.solve(g, 0.0, Load(), threshold_m=1e-12, relaxation="none")
    auto = statics.solve(g, 0.0, Load(), threshold_m=1e-12)
    sol = energy.solve_energy(g, 0.0, Load())
    assert not plain.converged and plain.iterations == statics.DEFAULT_MAX_ITERATIONS
    assert auto.converged and auto.iterations < 30
    np.testing.assert_allclose(auto.tip_m, sol.tip, atol=1e-10)


def test_auto_is_the_papers_iteration_while_it_contracts(geom: FingerGeometry) -> None:
    load = Load(payload_kg=3.0)
    auto = statics.solve(geom, 0.0, load)
    plain = statics.solve(geom, 0.0, load, relaxation="none")
    assert auto.iterations == plain.iterations
    np.testing.assert_array_equal(auto.tip_m, plain.tip_m)
    with pytest.raises(StaticsError, match="relaxation must be one of"):
        statics.solve(geom, 0.0, load, relaxation="newton")


@settings(max_examples=40, deadline=None)
@given(c=cases())
def test_printed_model_is_the_root_of_its_configuration_equation(c) -> None:
    g, q, kw = c
    load = Load(**kw)  # type: ignore[arg-type]
    k = tendons.stiffnesses(g)

    def residual(theta: np.ndarray) -> np.ndarray:
        tau = energy.load_torques(g, load, theta)
        # Steps 1-3 written out: T3 R3 = −τ3, (T2 − T3) R2 = −τ2, (T1 − T2) R1 = −τ1.
        t3 = -tau[2] / g.guide_radii_m[2]
        t2 = t3 - tau[1] / g.guide_radii_m[1]
        t1 = t2 - tau[0] / g.guide_radii_m[0]
        e = np.array([t1, t2, t3]) / k
        return np.array(g.guide_radii_m) * theta - (q - e)  # Eq. 16: R_i θ_i = q − e_i

    def jac(theta: np.ndarray) -> np.ndarray:  # central differences with an absolute step
        h = 1e-7
        return np.column_stack(
            [(residual(theta + h * e) - residual(theta - h * e)) / (2 * h) for e in np.eye(3)]
        )

    # Start off the rigid pose: MINPACK bounds its first step by the size of x0.
    sol = root(residual, kinematics.joint_angles(g, q) + 0.05, jac=jac, tol=1e-13)
    assert np.abs(residual(sol.x)).max() < 1e-13  # m of tendon: the root is found
    res = statics.solve(g, q, load, model="printed", threshold_m=1e-12)
    np.testing.assert_allclose(res.theta_rad, sol.x, atol=1e-9)


def test_tension_only_the_load_picks_the_group(geom: FingerGeometry) -> None:
    down = statics.solve(geom, 0.0, Load(tip_force_n=(0.0, -5.0), gravity=False))
    up = statics.solve(geom, 0.0, Load(tip_force_n=(0.0, 5.0), gravity=False))
    assert down.loaded_tendons == (1, 2, 3) and down.group == "flexion"
    assert up.loaded_tendons == (4, 5, 6) and up.group == "extension"
    # The groups mirror each other: the same tensions, reflected deflections.
    np.testing.assert_allclose(up.tensions_n, down.tensions_n, rtol=1e-9)
    np.testing.assert_allclose(up.tip_m * [1, -1], down.tip_m, atol=1e-12)
    assert down.motor_force_n[1] == 0 and up.motor_force_n[0] == 0
    assert down.motor_force_n[0] == pytest.approx(down.tensions_n[0])
    assert np.all(down.tensions_n >= 0) and np.all(up.tensions_n >= 0)


def test_a_tip_moment_loads_every_level_by_its_cumulative_ratio(geom: FingerGeometry) -> None:
    # A moment −M on Link 3 acts about every joint: N_k = M (1/R_k + ... + 1/R3).
    res = statics.solve(geom, 0.0, Load(tip_moment_nm=-0.2, gravity=False))
    c = np.cumsum((1.0 / geom.R)[::-1])[::-1]
    np.testing.assert_allclose(res.net_tensions_n, 0.2 * c, rtol=1e-9)


def test_mixed_groups_when_the_loads_turn_different_ways(geom: FingerGeometry) -> None:
    # A weight hanging from a finger curled past vertical: the distal joints are flexed by it
    # (extension tendons hold them) while Joint 1 is still pulled open (Tendon 1 holds it).
    # Steeply falling radii curl the distal links fastest, which puts this pose at 0.3.
    from dataclasses import replace

    geom = replace(geom, guide_radii_m=(0.010, 0.008, 0.006))
    q = 0.3 * geom.q_range_m[1]
    res = statics.solve(geom, q, Load(payload_kg=0.2, gravity=False))
    tau = statics.generalised_forces(
        geom, res.theta_rad, tip_force_n=(0.0, -0.2 * G), gravity=False
    )
    assert res.group == "mixed"
    for level, tendon in enumerate(res.loaded_tendons):
        n = -(tau[level:] / geom.R[level:]).sum()
        assert tendon == (level + 1 if n >= 0 else level + 4)


def test_without_load_the_finger_stays_on_the_kinematics(geom: FingerGeometry) -> None:
    res = statics.solve(geom, 0.005, Load(gravity=False))
    np.testing.assert_array_equal(res.theta_rad, kinematics.joint_angles(geom, 0.005))
    assert res.iterations == 1 and res.tip_deflection_m < 1e-15


def test_stiff_tendons_approach_the_rigid_finger(geom: FingerGeometry) -> None:
    from dataclasses import replace

    load = Load(payload_kg=1.0)
    d = [
        statics.solve(replace(geom, tendon_youngs_modulus_pa=e), 0.002, load).tip_deflection_m
        for e in (200e9, 2000e9, 20000e9)
    ]
    assert d[0] > d[1] > d[2]
    # Small deflections scale with compliance.
    assert d[1] / d[2] == pytest.approx(10.0, rel=0.02)


def test_serial_chains_the_stretches_printed_does_not(geom: FingerGeometry) -> None:
    e = np.array([1e-4, 2e-4, 3e-4])
    q = 0.004
    serial = statics.configuration(geom, q, e, "serial")
    printed = statics.configuration(geom, q, e, "printed")
    np.testing.assert_allclose(serial * geom.R, q - np.array([1e-4, 3e-4, 6e-4]))
    np.testing.assert_allclose(printed * geom.R, q - e)


def _joint_compliance(geom: FingerGeometry, model: str) -> np.ndarray:
    """dθ/dτ of external joint torques (no gravity), by finite differences at the straight pose."""
    base = statics.configuration(geom, 0.0, np.zeros(3), model)
    C = np.zeros((3, 3))
    for j in range(3):
        tau = np.zeros(3)
        tau[j] = 1e-3
        e = statics.elongations(geom, statics.net_tensions(geom, tau))
        C[:, j] = (statics.configuration(geom, 0.0, e, model) - base) / 1e-3
    return C


def test_serial_obeys_reciprocity_printed_does_not(geom: FingerGeometry) -> None:
    """Maxwell-Betti: a conservative structure has a symmetric compliance."""
    cs = _joint_compliance(geom, "serial")
    cp = _joint_compliance(geom, "printed")
    np.testing.assert_allclose(cs, cs.T, rtol=1e-9)
    assert np.abs(cp - cp.T).max() > 0.1 * np.abs(cp).max()
    # Positive definite: a load's torque turns the joints its way and stores energy.
    assert np.all(np.linalg.eigvalsh(cs) > 0)


def test_batch_equals_one_by_one(geom: FingerGeometry) -> None:
    rng = np.random.default_rng(3)
    n = 40
    q = rng.uniform(*geom.q_range_m, n)
    f = rng.normal(0, 5, (n, 2))
    m = rng.normal(0, 0.1, n)
    w = rng.uniform(0, 0.5, n)
    batch = statics.solve_batch(geom, q, payload_kg=w, tip_force_n=f, tip_moment_nm=m)
    for i in range(n):
        one = statics.solve(
            geom,
            float(q[i]),
            Load(payload_kg=float(w[i]), tip_force_n=tuple(f[i]), tip_moment_nm=float(m[i])),
        )
        np.testing.assert_array_equal(batch.tip[i], one.tip_m)
        assert batch.iterations[i] == one.iterations


def test_tighter_thresholds_take_more_iterations_and_meet_them(geom: FingerGeometry) -> None:
    load = Load(payload_kg=2.0)
    its = []
    for thr in (1e-4, 1e-6, 1e-8, 1e-10):
        res = statics.solve(geom, 0.0, load, threshold_m=thr)
        prev = statics.solve(
            geom, 0.0, load, threshold_m=thr, max_iterations=max(res.iterations - 1, 1)
        )
        its.append(res.iterations)
        assert res.converged
        if res.iterations > 1:
            # One pass fewer had not met the threshold yet.
            assert not prev.converged
    assert its == sorted(its) and its[-1] > its[0]


def test_warnings_for_overstress_overload_and_no_convergence(geom: FingerGeometry) -> None:
    heavy = statics.solve(geom, 0.0, Load(payload_kg=3.0))
    text = " ".join(heavy.warnings)
    assert "Tendon 1 would break" in text and "motor A" in text
    assert heavy.safety_factor[0] < 1 < heavy.safety_factor[2]
    assert heavy.stress_pa[0] == pytest.approx(heavy.tensions_n[0] / geom.tendon_area_m2)
    light = statics.solve(geom, 0.0, Load(payload_kg=0.05))
    assert light.warnings == ()
    cut = statics.solve(geom, 0.0, Load(payload_kg=3.0), max_iterations=2)
    assert not cut.converged and any("did not converge" in w for w in cut.warnings)
    soft = statics.solve(
        geom, 0.0, Load(payload_kg=0.2), limits=tendons.Limits(actuator_rated_force_n=10)
    )
    assert any("above its rated 10 N" in w for w in soft.warnings)


def test_warns_when_a_strand_would_leave_its_guide(geom: FingerGeometry) -> None:
    # The default keeps every strand wrapped over its whole range; radii falling as steeply as
    # 10/8/6 mm unwrap Tendon 3 at theta3 = 105 deg (flexion 0.70).
    from dataclasses import replace

    default_q = np.linspace(*geom.q_range_m, 41)
    assert not any(
        "leave" in w
        for q in default_q
        for w in statics.solve(geom, q, Load(gravity=False)).warnings
    )
    geom = replace(geom, guide_radii_m=(0.010, 0.008, 0.006))
    res = statics.solve(geom, 0.9 * geom.q_range_m[1], Load(gravity=False))
    assert any("Tendon 3 would leave" in w for w in res.warnings)
    ok = statics.solve(geom, 0.5 * geom.q_range_m[1], Load(gravity=False))
    assert not any("leave" in w for w in ok.warnings)


def test_json_is_si_and_complete(geom: FingerGeometry) -> None:
    import json

    out = statics.solve(geom, 0.0, Load(payload_kg=1.0)).to_json()
    for key in ("theta_rad", "tip_m", "tensions_n", "tip_deflection_m", "iterations", "model"):
        assert key in out
    json.dumps(out, allow_nan=False)
    slack = statics.solve(geom, 0.0, Load(gravity=False)).to_json()
    assert slack["safety_factor"] == [None, None, None]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"payload_kg": -1.0}, "payload_kg must be >= 0"),
        ({"grasp_force_n": -2.0}, "grasp_force_n must be >= 0"),
        ({"tip_force_n": (1.0,)}, "tip_force_n must be two"),
        ({"tip_moment_nm": float("inf")}, "tip_moment_nm must be a finite"),
    ],
)
def test_bad_loads_are_named(kwargs: dict, match: str) -> None:
    with pytest.raises(StaticsError, match=match):
        Load(**kwargs)


def test_bad_requests_are_named(geom: FingerGeometry) -> None:
    with pytest.raises(StaticsError, match="model must be one of"):
        statics.solve(geom, 0.0, model="elastic")
    with pytest.raises(StaticsError, match="threshold_m"):
        statics.solve(geom, 0.0, threshold_m=0.0)
    with pytest.raises(StaticsError, match="q must be a finite"):
        statics.solve(geom, float("nan"))
    with pytest.raises(StaticsError, match="broadcast"):
        statics.solve_batch(geom, np.zeros(3), payload_kg=np.zeros(4))
    with pytest.raises(StaticsError, match="payload_kg must be finite"):
        statics.solve_batch(geom, 0.0, payload_kg=[np.nan])


@settings(max_examples=20, deadline=None)
@given(g=geometries())
def test_energy_check_refuses_follower_loads(g: FingerGeometry) -> None:
    with pytest.raises(StaticsError, match="conservative"):
        energy.solve_energy(g, 0.0, Load(grasp_force_n=1.0))


@settings(max_examples=150, deadline=None)
@given(
    g=geometries(),
    data=st.data(),
    model=st.sampled_from(statics.MODELS),
    relaxation=st.sampled_from(statics.RELAXATIONS),
)
def test_the_fast_path_is_the_general_one_pass_for_pass(
    g: FingerGeometry, data: st.DataObject, model: str, relaxation: str
) -> None:
    """The passes' fast path (``statics_passes.passes_one``: plain floats, one case, what
    ``solve`` runs) and the general path (``passes``: numpy, what ``solve_batch`` runs) take the
    same passes to the same numbers, whatever the finger, load, model and relaxation."""
    lo, hi = g.q_range_m
    q = data.draw(st.floats(lo, hi))
    fx, fy = data.draw(st.floats(-10, 10)), data.draw(st.floats(-10, 10))
    fy -= data.draw(st.floats(0.0, 1.0)) * G  # a payload
    moment = data.draw(st.floats(-0.2, 0.2))
    grasp = data.draw(st.floats(0.0, 10.0))
    gravity = data.draw(st.booleans())
    solver = (1e-12, statics.DEFAULT_MAX_ITERATIONS, relaxation)
    theta, tips, net, stretch, iterations, converged = statics_passes.passes_one(
        g, q, fx, fy, moment, grasp, gravity, model == "serial", *solver
    )
    general = statics_passes.passes(
        g,
        np.array([q]),
        np.array([[fx, fy]]),
        np.array([moment]),
        np.array([grasp]),
        gravity,
        model,
        *solver,
    )
    assert iterations == general.iterations[0] and converged == general.converged[0]
    for mine, theirs in (
        (theta, general.theta[0]),
        (tips[:2], general.tip[0]),
        (tips[2:], general.tip_unloaded[0]),
        (net, general.net[0]),
        (stretch, general.stretch[0]),
    ):
        # Bit for bit where the trigonometric functions agree (they do on the machines
        # measured); the tolerance only allows a last-bit difference of sin/cos.
        np.testing.assert_allclose(mine, theirs, rtol=1e-13, atol=1e-18)


def test_check_gives_solves_warnings(geom: FingerGeometry) -> None:
    for load, q in ((Load(payload_kg=3.0), 0.0), (Load(payload_kg=0.05), 0.01)):
        res = statics.solve(geom, q, load)
        assert statics.check(res) == list(res.warnings)
    bent = statics.solve(geom, 0.0175, Load(), max_iterations=1)
    assert any("would leave" in w for w in bent.warnings) and not bent.converged
