"""Optional compiled backend: one fused numba kernel for a whole batched step.

It compiles the *same* model and controller functions as the numpy path
(``dynamics``, ``control``):
they are registered with numba (``register_jitable``) and called per vessel on
scalars, so the equations exist once. What the kernel adds is the loop: per
formation (in parallel), per vessel, the RK4 substeps of the level's closed
loop, then the masked observations, reward components and terminations, all
without temporaries. With non-ideal links the same loop then runs the
formation's channel instant (sensor noise, links, loss, delays, the held
messages, the observations through them) on the channel's arrays in place,
reading the same random rows as ``LinkChannel``;
formations that restart (autoreset) load their initial state instead of
stepping. On a curved path (docs/paths.md) the kernel also follows each
vessel's projection on the path (``paths.segment_project``, Newton from the
previous value after every RK4 step) and evaluates the loops, observations,
rewards and the corridor in path coordinates, as the numpy step does.
``FormationCore`` uses it when numba is
installed (``backend="auto"``) and keeps the numpy path as the reference
implementation; the tests check that both agree.
"""

from __future__ import annotations

import hashlib
import inspect
import math
import types
from collections import namedtuple
from typing import Any

import numpy as np
from numba import njit, prange
from numba.extending import register_jitable

from marine_formation_env import channel as channel_module
from marine_formation_env import control, dynamics, rules
from marine_formation_env import paths as paths_module
from marine_formation_env.rules import AGE, COORDINATION, LINK, OWN_SIZE, SLOT_SIZE, VELOCITY

__all__ = ["LEVEL_CODES", "StepKernel", "coefficients", "step_kernel"]

LEVEL_CODES = {"force": 0, "guidance": 1, "speed": 2}

Coeffs = namedtuple("Coeffs", "m11 m22 m23 m33 d11 d22 d23 d32 d33 lam")
GainsT = namedtuple("GainsT", "k_u k_psi k_r delta a")

for _fn in (
    dynamics.accelerations,
    dynamics.current_velocity,
    dynamics.vessel_derivatives,
    dynamics.wrap_angle,
    control.saturation,
    control.los_angle,
    control.surge_law,
    control.yaw_law,
    control.los_yaw_reference,
    control.heading_yaw_reference,
    control.path_following_inputs,
    control.heading_tracking_inputs,
    control._sway_coupling,
    control._sway_damping,
    control.turn_sway,
    control.turn_crab,
    control.path_rates,
    control.curved_path_following_inputs,
    control.curved_heading_inputs,
    paths_module.segment_frame,
    paths_module.segment_project,
    rules.rk4_combine,
    rules.along_track,
    rules.slot_differences,
    rules.bounded_cost,
    rules.cost_term,
    rules.effort_term,
    rules.terminal_term,
    rules.outside_workspace,
    rules.outside_envelope,
    channel_module.in_range,
    channel_module.prediction_error,
    channel_module.event_due,
):
    register_jitable(_fn)

accelerations = dynamics.accelerations
current_velocity = dynamics.current_velocity
vessel_derivatives = dynamics.vessel_derivatives
wrap_angle = dynamics.wrap_angle
path_following_inputs = control.path_following_inputs
heading_tracking_inputs = control.heading_tracking_inputs
curved_path_following_inputs = control.curved_path_following_inputs
curved_heading_inputs = control.curved_heading_inputs
segment_frame = paths_module.segment_frame
segment_project = paths_module.segment_project
rk4_combine = rules.rk4_combine
along_track = rules.along_track
slot_differences = rules.slot_differences
cost_term = rules.cost_term
effort_term = rules.effort_term
terminal_term = rules.terminal_term
outside_workspace = rules.outside_workspace
outside_envelope = rules.outside_envelope
in_range = channel_module.in_range
prediction_error = channel_module.prediction_error
event_due = channel_module.event_due
NEVER = channel_module.NEVER
NOT_SENT = channel_module.NOT_SENT


def coefficients(config: Any) -> tuple[Any, Any]:
    """The vessel and gain values of ``config`` as the tuples the kernel takes."""
    p, g = config.params, config.gains
    return (
        Coeffs(p.m11, p.m22, p.m23, p.m33, p.d11, p.d22, p.d23, p.d32, p.d33, p.lam),
        GainsT(g.k_u, g.k_psi, g.k_r, g.delta, g.a),
    )


@njit(cache=True, inline="always")
def _clip(x: float, lo: float, hi: float) -> float:
    return min(max(x, lo), hi)


@njit(cache=True, inline="always")
def _derivative(level, p, g, printed, d_y, y, psi, u, v, r, cmd0, cmd1, t, u_c0, u_c_dot, tu_max, tr_max, sea):  # type: ignore[no-untyped-def]
    """The closed loop of one vessel (the numpy path's ``FormationCore.closed_loop``).

    ``sea = (t0, speed, amplitude, ω, cos β, sin β)``: the period's start time and the current.
    """
    t0, c_speed, c_amp, c_omega, c_cos, c_sin = sea
    if level == 0:
        tau_u, tau_r = cmd0, cmd1
        acc = accelerations(p, u, v, r)
    else:
        acc = accelerations(p, u, v, r)
        if level == 1:
            tau_u, tau_r = heading_tracking_inputs(p, g, cmd1, psi, u, v, r, u_c0 + u_c_dot * t, u_c_dot, printed, acc)
        else:
            tau_u, tau_r = path_following_inputs(p, g, y - d_y, psi, u, v, r, u_c0 + u_c_dot * t, u_c_dot, printed, acc)
        tau_u, tau_r = _clip(tau_u, -tu_max, tu_max), _clip(tau_r, -tr_max, tr_max)
    if c_speed == 0.0 and c_amp == 0.0:  # still water (Current.is_zero): no current term, as in the numpy path
        return vessel_derivatives(p, psi, u, v, r, tau_u, tau_r, acc, None, None)
    vc_x, vc_y = current_velocity(c_speed, c_amp, c_omega, c_cos, c_sin, t0 + t)
    return vessel_derivatives(p, psi, u, v, r, tau_u, tau_r, acc, vc_x, vc_y)


@njit(cache=True, inline="always")
def _curved_derivative(  # type: ignore[no-untyped-def]
    level, p, g, s0, sx, sy, sg, sk, guess, steer, x, y, psi, u, v, r, cmd1, t, u_c0, u_c_dot, tu_max, tr_max, sea
):
    """The closed loop of one vessel on a curved path (``speed``, ``guidance``; ``FormationCore._closed_loop_curved``).

    Its path coordinates come from the stage's position, projected from ``guess`` (the step's start).
    """
    t0, c_speed, c_amp, c_omega, c_cos, c_sin = sea
    _, offset, beta, kappa, metric, _, _, _ = _path_point(s0, sx, sy, sg, sk, x, y, psi, u, v, guess)
    acc = accelerations(p, u, v, r)
    u_c = u_c0 + u_c_dot * t
    if level == 1:
        tau_u, tau_r = curved_heading_inputs(p, g, cmd1, beta, kappa, metric, u, v, r, u_c, u_c_dot, acc)
    else:
        tau_u, tau_r = curved_path_following_inputs(
            p, g, offset - steer, beta, kappa, metric, u, v, r, u_c, u_c_dot, acc
        )
    tau_u, tau_r = _clip(tau_u, -tu_max, tu_max), _clip(tau_r, -tr_max, tr_max)
    if c_speed == 0.0 and c_amp == 0.0:
        return vessel_derivatives(p, psi, u, v, r, tau_u, tau_r, acc, None, None)
    vc_x, vc_y = current_velocity(c_speed, c_amp, c_omega, c_cos, c_sin, t0 + t)
    return vessel_derivatives(p, psi, u, v, r, tau_u, tau_r, acc, vc_x, vc_y)


@njit(cache=True, inline="always")
def _curved_stage(  # type: ignore[no-untyped-def]
    level, p, g, s0, sx, sy, sg, sk, guess, steer,
    x, y, psi, u, v, r, k, step, cmd1, t, u_c0, u_c_dot, tu_max, tr_max, sea,
):  # fmt: skip
    """``_curved_derivative`` at the RK4 stage state ``(x, y, ψ, u, v, r) + step·k``."""
    return _curved_derivative(
        level, p, g, s0, sx, sy, sg, sk, guess, steer,
        x + step * k[0], y + step * k[1], psi + step * k[2], u + step * k[3], v + step * k[4], r + step * k[5],
        cmd1, t, u_c0, u_c_dot, tu_max, tr_max, sea,
    )  # fmt: skip


@njit(cache=True, inline="always")
def _path_point(s0, sx, sy, sg, sk, x, y, psi, u, v, guess):  # type: ignore[no-untyped-def]
    """``(ℓ, e + D_y, β, κ, 1 − κ·d, u cos β − v sin β, cos γ, sin γ)`` of one vessel (``paths.path_coordinates``)."""
    ell = segment_project(s0, sx, sy, sg, sk, x, y, guess)
    px, py, gamma, kappa = segment_frame(s0, sx, sy, sg, sk, ell)
    c, s = math.cos(gamma), math.sin(gamma)
    offset = (y - py) * c - (x - px) * s
    beta = psi - gamma
    return ell, offset, beta, kappa, 1.0 - kappa * offset, u * math.cos(beta) - v * math.sin(beta), c, s


@njit(cache=True, inline="always")
def _stage(fixed, y, psi, u, v, r, k, step, t):  # type: ignore[no-untyped-def]
    """The closed loop at the RK4 stage state ``(y, ψ, u, v, r) + step·k`` (x does not enter it)."""
    level, p, g, printed, d_y, c0, c1, uc0, uc_dot, tu_max, tr_max, sea = fixed
    return _derivative(
        level,
        p,
        g,
        printed,
        d_y,
        y + step * k[1],
        psi + step * k[2],
        u + step * k[3],
        v + step * k[4],
        r + step * k[5],
        c0,
        c1,
        t,
        uc0,
        uc_dot,
        tu_max,
        tr_max,
        sea,
    )


def _kernel(  # type: ignore[no-untyped-def]
    state,  # (B, N, 6) float64, updated in place
    cmd,  # (B, N, 2) physical commands: (τ_u, τ_r) | (u_c, ψ_d) | (u_c, 0)
    u_c0,  # (B, N) previous u_c (first-order hold)
    level,
    p,
    g,
    printed,
    dt,
    substeps,
    tu_max,
    tr_max,
    current,  # (speed, amplitude, ω, cos β, sin β) of the ocean current
    time0,  # (B,) time at the start of the period
    steer_dy,  # (B, N) the path offset the built-in LOS steers to (D_y, shifted by integral LOS)
    offsets,  # (N, 2)
    slot_index,  # (N, N-1)
    slot_mask,  # (N, N-1) float
    u_d,  # (B,) u_d at the new time
    u_d_rate,  # (B,)
    time_left,  # (B,) horizon − new time
    obs_low,  # (D,) float32
    obs_high,  # (D,) float32
    weights,  # (5,) cross_track, heading, coordination, speed, effort
    scales,  # (9,) the four σ, the four fine shares (RewardConfig.fine_shares), then fine_scale
    actions,  # (B, N, A) clipped normalized actions (for the effort term)
    terminal_penalty,  # worst remaining reward rate (Σ weights), 0 if off
    workspace,  # (4,)
    safety,
    max_speed,
    max_yaw_rate,
    obs,  # (B, N, D) float32 out
    comps,  # (6, B, N) out
    reward,  # (B, N) out: the sum of the components
    flags,  # (B, 2) bool out: collision, out_of_bounds
    theta,  # (B, N) scratch: x − D_x
    xdot,  # (B, N) scratch: ẋ
    restart,  # (B,) bool: start a new episode from `initial` instead of stepping (autoreset)
    initial,  # (B, N, 6) initial states of the restarting formations (other rows unused)
    time1,  # (B,) time at the end of the period (0 for restarting formations)
    steps,  # (B,) control periods since reset, after this step (0 for restarting formations)
    channel_on,  # the links are not ideal: the channel's functions write the observations
    chan,  # the channel's constants, state and streams (ChannelArgs); placeholders with ideal links
    curved,  # the path is not the paper's straight line (docs/paths.md)
    seg_start,  # (K,) the path's segments (Path.segment_arrays)
    seg_x0,
    seg_y0,
    seg_g0,
    seg_k,
    arc,  # (B, N) each vessel's projection ℓ on the path, updated in place (curved paths)
    corridor,  # largest |e| before a vessel is out of bounds (curved paths)
    lookahead,  # [m] where the observation's curvature ahead is taken
    pscr,  # (B, N, 4) scratch: e, β, κ, κ ahead (curved paths)
):
    n_form, n = state.shape[0], state.shape[1]
    h = dt / substeps
    # the channel's arrays, unpacked once (the threads cannot share tuples of arrays)
    (noise, c_sea, c_rule, c_graphs, c_ends, c_loss, c_uniforms, c_upos, c_link, c_pending, c_bounds, c_traffic) = chan
    has_noise, c_normals, c_npos, c_scale, c_measured = noise
    has_current, c_current = c_sea
    c_up, c_has, c_theta, c_xdot, c_time, c_failed, c_bad, c_tx = c_link
    c_pvalid, c_ptheta, c_pxdot, c_ptime, c_next = c_pending
    c_slots, c_low, c_high = c_bounds
    t_rule, t_wants, t_stheta, t_sxdot, t_stime, t_sstep, t_tokens, t_counts = c_traffic
    t_bucket = t_rule[6]
    c_with_burst, c_p_bad, c_depth = c_rule[5], c_rule[8], c_rule[15]
    for b in prange(n_form):
        if restart[b]:
            for j in range(n):
                for m in range(6):
                    state[b, j, m] = initial[b, j, m]
        # ---- integrate every vessel of formation b over one control period
        for j in range(n if not restart[b] else 0):
            x, y, psi, u, v, r = (
                state[b, j, 0],
                state[b, j, 1],
                state[b, j, 2],
                state[b, j, 3],
                state[b, j, 4],
                state[b, j, 5],
            )
            c0, c1, uc0 = cmd[b, j, 0], cmd[b, j, 1], u_c0[b, j]
            uc_dot = (c0 - uc0) / dt
            d_y = steer_dy[b, j]
            sea = (time0[b], current[0], current[1], current[2], current[3], current[4])
            guess = arc[b, j]
            for k in range(substeps):
                t = k * h
                hh = 0.5 * h
                if curved and level != 0:  # the loops in path coordinates (every stage projects from `guess`)
                    k1 = _curved_derivative(
                        level, p, g, seg_start, seg_x0, seg_y0, seg_g0, seg_k, guess, d_y,
                        x, y, psi, u, v, r, c1, t, uc0, uc_dot, tu_max, tr_max, sea,
                    )  # fmt: skip
                    k2 = _curved_stage(
                        level, p, g, seg_start, seg_x0, seg_y0, seg_g0, seg_k, guess, d_y,
                        x, y, psi, u, v, r, k1, hh, c1, t + hh, uc0, uc_dot, tu_max, tr_max, sea,
                    )  # fmt: skip
                    k3 = _curved_stage(
                        level, p, g, seg_start, seg_x0, seg_y0, seg_g0, seg_k, guess, d_y,
                        x, y, psi, u, v, r, k2, hh, c1, t + hh, uc0, uc_dot, tu_max, tr_max, sea,
                    )  # fmt: skip
                    k4 = _curved_stage(
                        level, p, g, seg_start, seg_x0, seg_y0, seg_g0, seg_k, guess, d_y,
                        x, y, psi, u, v, r, k3, h, c1, t + h, uc0, uc_dot, tu_max, tr_max, sea,
                    )  # fmt: skip
                else:
                    fixed = (level, p, g, printed, d_y, c0, c1, uc0, uc_dot, tu_max, tr_max, sea)
                    k1 = _derivative(
                        level, p, g, printed, d_y, y, psi, u, v, r, c0, c1, t, uc0, uc_dot, tu_max, tr_max, sea
                    )
                    k2 = _stage(fixed, y, psi, u, v, r, k1, hh, t + hh)
                    k3 = _stage(fixed, y, psi, u, v, r, k2, hh, t + hh)
                    k4 = _stage(fixed, y, psi, u, v, r, k3, h, t + h)
                x = rk4_combine(x, k1[0], k2[0], k3[0], k4[0], h)
                y = rk4_combine(y, k1[1], k2[1], k3[1], k4[1], h)
                psi = rk4_combine(psi, k1[2], k2[2], k3[2], k4[2], h)
                u = rk4_combine(u, k1[3], k2[3], k3[3], k4[3], h)
                v = rk4_combine(v, k1[4], k2[4], k3[4], k4[4], h)
                r = rk4_combine(r, k1[5], k2[5], k3[5], k4[5], h)
                if curved:  # follow the projection: Newton from where it was
                    guess = segment_project(seg_start, seg_x0, seg_y0, seg_g0, seg_k, x, y, guess)
            arc[b, j] = guess
            state[b, j, 0], state[b, j, 1], state[b, j, 2] = x, y, psi
            state[b, j, 3], state[b, j, 4], state[b, j, 5] = u, v, r

        # ---- formation quantities
        theta_mean = 0.0
        for j in range(n):
            if curved:
                ell, off, beta, kap, metric, along, _c, _s = _path_point(
                    seg_start, seg_x0, seg_y0, seg_g0, seg_k,
                    state[b, j, 0], state[b, j, 1], state[b, j, 2], state[b, j, 3], state[b, j, 4], arc[b, j],
                )  # fmt: skip
                theta[b, j], xdot[b, j] = ell - offsets[j, 0], along / metric
                pscr[b, j, 0], pscr[b, j, 1], pscr[b, j, 2] = off - offsets[j, 1], beta, kap
                pscr[b, j, 3] = segment_frame(seg_start, seg_x0, seg_y0, seg_g0, seg_k, ell + lookahead)[3]
            else:
                theta[b, j], xdot[b, j] = along_track(
                    state[b, j, 0], offsets[j, 0], state[b, j, 2], state[b, j, 3], state[b, j, 4]
                )
            theta_mean += theta[b, j]
        theta_mean /= n
        out_of_bounds = False
        min_sep = np.inf
        for j in range(n):
            sx, sy = state[b, j, 0], state[b, j, 1]
            if outside_workspace(sx, sy, workspace[0], workspace[1], workspace[2], workspace[3]):
                out_of_bounds = True
            if outside_envelope(state[b, j, 3], state[b, j, 4], state[b, j, 5], max_speed, max_yaw_rate):
                out_of_bounds = True
            for m in range(6):
                if not np.isfinite(state[b, j, m]):
                    out_of_bounds = True
            if curved and abs(pscr[b, j, 0]) > corridor:  # far from its lane
                out_of_bounds = True
            for i in range(j + 1, n):
                d = np.hypot(sx - state[b, i, 0], sy - state[b, i, 1])
                min_sep = min(min_sep, d)
        collision = min_sep < safety and not restart[b]
        out_of_bounds = out_of_bounds and not restart[b]
        terminated = collision or out_of_bounds
        flags[b, 0] = collision
        flags[b, 1] = out_of_bounds

        # ---- observations and rewards
        for j in range(n):
            u_j, v_j = state[b, j, 3], state[b, j, 4]
            theta_j, xdot_j = theta[b, j], xdot[b, j]
            if curved:
                e_j, psi_w, kap_j, ahead_j = pscr[b, j, 0], wrap_angle(pscr[b, j, 1]), pscr[b, j, 2], pscr[b, j, 3]
            else:  # the straight path: no curvature now or ahead
                e_j, psi_w, kap_j, ahead_j = state[b, j, 1] - offsets[j, 1], wrap_angle(state[b, j, 2]), 0.0, 0.0
            own = (e_j, psi_w, u_j, v_j, state[b, j, 5], u_d[b], u_d_rate[b], kap_j, ahead_j, offsets[j, 1])
            for f in range(OWN_SIZE if not (channel_on and has_noise) else 0):  # else: from the measurement
                obs[b, j, f] = _clip(own[f], obs_low[f], obs_high[f])
            for kk in range(n - 1 if not channel_on else 0):
                i = slot_index[j, kk]
                base = OWN_SIZE + SLOT_SIZE * kk
                link = slot_mask[j, kk]
                d_theta, d_xdot = slot_differences(link, theta_j, theta[b, i], xdot_j, xdot[b, i])
                obs[b, j, base + LINK] = link
                obs[b, j, base + COORDINATION] = _clip(
                    d_theta, obs_low[base + COORDINATION], obs_high[base + COORDINATION]
                )
                obs[b, j, base + VELOCITY] = _clip(d_xdot, obs_low[base + VELOCITY], obs_high[base + VELOCITY])
                obs[b, j, base + AGE] = 0.0
            errors = (e_j, psi_w, theta_j - theta_mean, xdot_j - u_d[b])
            for c in range(4):
                comps[c, b, j] = cost_term(weights[c], errors[c], scales[c], dt, scales[4 + c], scales[8])
            sq = 0.0
            for f in range(actions.shape[2]):
                sq += actions[b, j, f] * actions[b, j, f]
            comps[4, b, j] = effort_term(weights[4], sq / actions.shape[2], dt)
            comps[5, b, j] = terminal_term(terminated, terminal_penalty, time_left[b])
            total = 0.0
            for c in range(6):
                if restart[b]:  # the first output of an episode carries no reward
                    comps[c, b, j] = 0.0
                total += comps[c, b, j]
            reward[b, j] = total
        if channel_on:
            # the channel's control instant, in the numpy path's order (FormationCore._sense, and for a
            # restarting formation LinkChannel.reset first, then update and observe), on the same rows of
            # uniforms and normals. Its arrays go one by one to small inlined functions: packing them in
            # a tuple per formation (the threads cannot share the outer tuple) cost about twice the
            # channel's own arithmetic at B = 8192 (docs/throughput.md).
            t1, step = time1[b], steps[b]
            if restart[b]:
                _channel_restart(
                    b,
                    c_depth,
                    c_with_burst,
                    c_p_bad,
                    c_uniforms,
                    c_upos,
                    c_tx,
                    c_up,
                    c_has,
                    c_failed,
                    c_theta,
                    c_xdot,
                    c_time,
                    c_pvalid,
                    c_next,
                    c_bad,
                    t_stheta,
                    t_sxdot,
                    t_stime,
                    t_sstep,
                    t_tokens,
                    t_bucket,
                )
            if has_noise:  # without noise the measurement is the state, whose theta, xdot the step left
                _channel_measure(b, state, c_normals, c_npos, c_scale, c_measured, offsets, theta, xdot)
            if curved:  # what is transmitted and observed: θ = ℓ − D_x and ℓ̇ over ground of the measurement
                vc_x, vc_y = 0.0, 0.0
                if has_current:
                    vc_x, vc_y = current_velocity(
                        c_current[0], c_current[1], c_current[2], c_current[3], c_current[4], t1
                    )
                for j in range(n):
                    src = c_measured if has_noise else state
                    ell, off, beta, kap, metric, along, cg, sg = _path_point(
                        seg_start, seg_x0, seg_y0, seg_g0, seg_k,
                        src[b, j, 0], src[b, j, 1], src[b, j, 2], src[b, j, 3], src[b, j, 4], arc[b, j],
                    )  # fmt: skip
                    theta[b, j] = ell - offsets[j, 0]
                    xdot[b, j] = (along + vc_x * cg + vc_y * sg) / metric if has_current else along / metric
                    if has_noise:  # the own part from the measurement
                        ahead = segment_frame(seg_start, seg_x0, seg_y0, seg_g0, seg_k, ell + lookahead)[3]
                        own = (
                            off - offsets[j, 1], wrap_angle(beta), src[b, j, 3], src[b, j, 4], src[b, j, 5],
                            u_d[b], u_d_rate[b], kap, ahead, offsets[j, 1],
                        )  # fmt: skip
                        for f in range(OWN_SIZE):
                            obs[b, j, f] = _clip(own[f], obs_low[f], obs_high[f])
            elif has_current:  # the inertial ẋ carries the current
                vc_x = current_velocity(c_current[0], c_current[1], c_current[2], c_current[3], c_current[4], t1)[0]
                for j in range(n):
                    xdot[b, j] += vc_x
            _channel_send(
                b,
                state,
                t1,
                step,
                c_rule,
                c_graphs,
                c_ends,
                c_loss,
                c_uniforms,
                c_upos,
                c_up,
                c_failed,
                c_bad,
                c_tx,
                c_pvalid,
                c_ptheta,
                c_pxdot,
                c_ptime,
                c_next,
                theta,
                xdot,
                t_rule,
                t_wants,
                t_stheta,
                t_sxdot,
                t_stime,
                t_sstep,
                t_tokens,
                t_counts,
            )
            if step >= c_next[b]:  # the ring of pending messages is read only at an instant where one arrives
                _channel_deliver(
                    b, step, c_depth, c_has, c_theta, c_xdot, c_time, c_pvalid, c_ptheta, c_pxdot, c_ptime, c_next
                )
            _channel_observe(
                b,
                t1,
                has_noise and not curved,  # on a curved path the own part is written above
                c_measured,
                offsets,
                u_d,
                u_d_rate,
                c_up,
                c_has,
                c_theta,
                c_xdot,
                c_time,
                theta,
                xdot,
                c_slots,
                c_low,
                c_high,
                obs,
            )


@njit(inline="always")
def _channel_restart(  # type: ignore[no-untyped-def]
    b,
    depth,
    with_burst,
    p_bad,
    uniforms,
    upos,
    transmitted,
    up,
    has_message,
    failed,
    held_theta,
    held_xdot,
    held_time,
    pend_valid,
    next_arrival,
    bad,
    sent_theta,
    sent_xdot,
    sent_time,
    sent_step,
    tokens,
    bucket,
):
    """``LinkChannel.reset`` for formation ``b``: no messages, every link live, Gilbert–Elliott chains stationary,
    nothing broadcast, full buckets."""
    n = up.shape[1]
    for j in range(n):
        transmitted[b, j] = False
        sent_theta[b, j] = np.inf
        sent_xdot[b, j] = sent_time[b, j] = 0.0
        sent_step[b, j] = -NOT_SENT
        tokens[b, j] = bucket
        for i in range(n):
            up[b, j, i] = has_message[b, j, i] = failed[b, j, i] = False
            held_theta[b, j, i] = held_xdot[b, j, i] = held_time[b, j, i] = 0.0
    if next_arrival[b] != NEVER:  # messages on their way (else the ring is clear: no read)
        for d in range(depth):
            for j in range(n):
                for i in range(n):
                    pend_valid[b, d, j, i] = False
        next_arrival[b] = NEVER
    if with_burst:
        r0 = uniforms[b, upos[b]]
        upos[b] += 1
        for k in range(n * n):
            bad[b, k // n, k % n] = r0[k] < p_bad


@njit(inline="always")
def _channel_measure(b, state, normals, npos, scale, measured, offsets, theta, xdot):  # type: ignore[no-untyped-def]
    """What each vessel of ``b`` measures of itself (``SensorNoiseSource``): the state plus a row of normals.

    Leaves θ and ẋ (body-frame ẋ, before the current) of the measured state in ``theta``, ``xdot``.
    """
    row = npos[b]
    for j in range(state.shape[1]):
        for c in range(6):
            measured[b, j, c] = state[b, j, c] + normals[b, row, 6 * j + c] * scale[c]
        theta[b, j], xdot[b, j] = along_track(
            measured[b, j, 0], offsets[j, 0], measured[b, j, 2], measured[b, j, 3], measured[b, j, 4]
        )
    npos[b] = row + 1


@njit(inline="always")
def _channel_send(  # type: ignore[no-untyped-def]
    b,
    state,
    t,
    step,
    rule,
    graphs,
    ends,
    loss,
    uniforms,
    upos,
    up,
    failed,
    bad,
    transmitted,
    pend_valid,
    pend_theta,
    pend_xdot,
    pend_time,
    next_arrival,
    theta,
    xdot,
    traffic,
    wants,
    sent_theta,
    sent_xdot,
    sent_time,
    sent_step,
    tokens,
    counts,
):
    """``LinkChannel.update`` for formation ``b``: who broadcasts (``LinkChannel._broadcasts``), link states,
    losses, delays into the ring, and the message counters."""
    (
        tdma,
        every,
        with_failure,
        p_fail,
        p_recover,
        with_burst,
        p_gb,
        p_bg,
        _p_bad,
        loss_good,
        loss_bad,
        latency,
        jitter,
        with_delay,
        max_delay_steps,
        depth,
        dt,
        link_range,
        with_range,
    ) = rule
    n = up.shape[1]
    nn = n * n
    # which part of a row of uniforms holds which draw: failure, Gilbert-Elliott, loss, jitter
    d_fail = 0
    d_burst = d_fail + (1 if with_failure else 0)
    d_loss = d_burst + (1 if with_burst else 0)
    d_jitter = d_loss + 1
    g = 0
    if graphs.shape[0] > 1:
        phase = (t + 1e-9) % ends[-1]
        while g < ends.shape[0] and ends[g] <= phase:
            g += 1
    mode, threshold, min_steps, heartbeat_steps, with_budget, refill, bucket, bits = traffic
    draws = with_failure  # a row of uniforms only when something random happens (LinkChannel.draws_at)
    for i in range(n):
        if tdma:
            opportunity = step % (n * every) == i * every
        else:
            opportunity = step % every == 0
        if mode == 2:  # the policy decides; at reset there is no decision yet: every vessel tries
            attempt = wants[b, i] or step == 0
            clear = attempt and opportunity
        elif mode == 1:  # event-triggered
            clear = False
            if opportunity:
                error = prediction_error(
                    theta[b, i], xdot[b, i], sent_theta[b, i], sent_xdot[b, i], t - sent_time[b, i]
                )
                clear = event_due(error, threshold, step - sent_step[b, i], min_steps, heartbeat_steps)
            attempt = clear
        else:
            attempt = clear = opportunity
        tx = clear
        if with_budget:
            level = bucket if step == 0 else min(tokens[b, i] + refill, bucket)
            tx = clear and level >= bits
            tokens[b, i] = level - bits if tx else level
        transmitted[b, i] = tx
        counts[b, 0, i] = 1 if attempt else 0
        counts[b, 1, i] = 1 if tx else 0
        counts[b, 2, i] = counts[b, 3, i] = counts[b, 4, i] = 0
        counts[b, 5, i] = 1 if attempt and not clear else 0
        counts[b, 6, i] = 1 if clear and not tx else 0
        if tx:
            sent_theta[b, i], sent_xdot[b, i], sent_time[b, i], sent_step[b, i] = theta[b, i], xdot[b, i], t, step
        draws = draws or tx
    r = uniforms[b, upos[b]]  # not read (and not consumed) without draws
    if draws:
        upos[b] += 1
    for j in range(n):
        for i in range(n):
            k = j * n + i
            alive = graphs[g, j, i]
            if with_range and alive:
                alive = in_range(state[b, j, 0] - state[b, i, 0], state[b, j, 1] - state[b, i, 1], link_range)
            if with_failure:
                u_f = r[d_fail * nn + k]
                if step == 0:  # every link is live at reset
                    down = False
                elif failed[b, j, i]:
                    down = u_f >= p_recover
                else:
                    down = u_f < p_fail
                failed[b, j, i] = down
                alive = alive and not down
            up[b, j, i] = alive
            if not transmitted[b, i]:
                continue
            if not alive:
                if graphs[g, j, i]:  # a link of the graph, down: out of range or failed
                    counts[b, 4, i] += 1
                continue
            if with_burst:
                u_b = r[d_burst * nn + k]
                in_bad = u_b >= p_bg if bad[b, j, i] else u_b < p_gb
                bad[b, j, i] = in_bad
                p_loss = loss_bad if in_bad else loss_good
            else:
                p_loss = loss[j, i]
            if r[d_loss * nn + k] < p_loss:
                counts[b, 3, i] += 1
                continue
            counts[b, 2, i] += 1
            delay_steps = 0
            if with_delay:
                delay = latency + (jitter * r[d_jitter * nn + k] if jitter > 0 else 0.0)
                delay_steps = math.ceil(delay / dt - 1e-9)
            if delay_steps <= max_delay_steps:  # later than the episode's end: never seen
                slot = (step + delay_steps) % depth
                pend_valid[b, slot, j, i] = True
                pend_theta[b, slot, j, i] = theta[b, i]
                pend_xdot[b, slot, j, i] = xdot[b, i]
                pend_time[b, slot, j, i] = t
                next_arrival[b] = min(next_arrival[b], step + delay_steps)


@njit(inline="always")
def _channel_deliver(  # type: ignore[no-untyped-def]
    b,
    step,
    depth,
    has_message,
    held_theta,
    held_xdot,
    held_time,
    pend_valid,
    pend_theta,
    pend_xdot,
    pend_time,
    next_arrival,
):
    """The messages of ``b`` that arrive at ``step`` (zero-delay ones sent just now included): newest kept."""
    n = has_message.shape[1]
    now = step % depth
    for j in range(n):
        for i in range(n):
            if pend_valid[b, now, j, i]:
                if not has_message[b, j, i] or pend_time[b, now, j, i] > held_time[b, j, i]:
                    held_theta[b, j, i] = pend_theta[b, now, j, i]
                    held_xdot[b, j, i] = pend_xdot[b, now, j, i]
                    held_time[b, j, i] = pend_time[b, now, j, i]
                    has_message[b, j, i] = True
                pend_valid[b, now, j, i] = False
    following = NEVER
    for d in range(depth):
        for j in range(n):
            for i in range(n):
                if pend_valid[b, d, j, i]:
                    following = min(following, step + (d - step) % depth)
    next_arrival[b] = following


@njit(inline="always")
def _channel_observe(  # type: ignore[no-untyped-def]
    b,
    t,
    has_noise,
    measured,
    offsets,
    u_d,
    u_d_rate,
    up,
    has_message,
    held_theta,
    held_xdot,
    held_time,
    theta,
    xdot,
    slot_index,
    obs_low,
    obs_high,
    obs,
):
    """The observations of ``b`` through the channel (``LinkChannel.slots``): own measurement, held messages.

    Without sensor noise the step already wrote the own part (the measurement is the state).
    """
    n = up.shape[1]
    for j in range(n):
        if has_noise:
            own = (
                measured[b, j, 1] - offsets[j, 1],
                wrap_angle(measured[b, j, 2]),
                measured[b, j, 3],
                measured[b, j, 4],
                measured[b, j, 5],
                u_d[b],
                u_d_rate[b],
                0.0,
                0.0,
                offsets[j, 1],
            )
            for f in range(OWN_SIZE):
                obs[b, j, f] = _clip(own[f], obs_low[f], obs_high[f])
        for kk in range(n - 1):
            i = slot_index[j, kk]
            base = OWN_SIZE + SLOT_SIZE * kk
            if up[b, j, i] and has_message[b, j, i]:
                feats = (
                    1.0,
                    theta[b, j] - held_theta[b, j, i],
                    xdot[b, j] - held_xdot[b, j, i],
                    t - held_time[b, j, i],
                )
            else:
                feats = (0.0, 0.0, 0.0, 0.0)
            for f in range(SLOT_SIZE):
                obs[b, j, base + f] = _clip(feats[f], obs_low[base + f], obs_high[base + f])


def _renamed(fn: Any, name: str) -> Any:
    """A copy of ``fn`` under another name, so numba caches its two compilations apart."""
    copy = types.FunctionType(fn.__code__, fn.__globals__, name, fn.__defaults__, fn.__closure__)
    copy.__qualname__ = name
    return copy


def source_key() -> str:
    """A digest of the sources the kernel compiles in besides this file's (model, controllers, step rules).

    numba's on-disk cache is invalidated only when the file that holds the
    jitted function changes, not when a function it calls from another module
    does. The kernels' names carry this digest, so an edit of a rule in
    ``rules`` (or of the model, a controller or the
    channel's ``in_range``)
    compiles a new kernel instead of loading a stale one from the cache.
    """
    digest = hashlib.sha256()
    for module in (dynamics, control, rules, channel_module, paths_module):
        digest.update(inspect.getsource(module).encode())
    return digest.hexdigest()[:16]


_KEY = source_key()
_serial = njit(cache=True)(_renamed(_kernel, f"_kernel_{_KEY}"))
_parallel = njit(cache=True, parallel=True)(_renamed(_kernel, f"_kernel_parallel_{_KEY}"))

#: Formations from which the multi-threaded kernel is used.
PARALLEL_FROM = 64


def step_kernel(n_formations: int) -> Any:
    """The kernel to use for ``n_formations`` formations (threads only pay off for many)."""
    return _parallel if n_formations >= PARALLEL_FROM else _serial


class StepKernel:
    """The compiled step of one ``FormationCore``: its arguments packed once.

    Everything the kernel needs that does not change between steps (the
    vessel, the gains, the level, the limits, the reward weights, the
    observation bounds and slot geometry, the channel's constants) is packed
    at construction; ``run``
    passes the per-step arrays.

    With non-ideal links (``channel`` given) the same kernel also runs the
    channel's control instant for each formation right after its step, on the
    arrays of the core's ``LinkChannel``
    and ``SensorNoiseSource`` in place:
    the numpy path (which still serves
    ``reset``) and the kernel
    share one channel state, and the kernel reads their block streams of
    uniforms and normals row by row, as their ``take`` does, so both draw the
    same numbers in the same order.
    """

    def __init__(
        self,
        config: Any,
        num_envs: int,
        slot_index: np.ndarray,
        slot_mask: np.ndarray,
        obs_low: np.ndarray,
        obs_high: np.ndarray,
        channel: Any = None,
        sensor_noise: Any = None,
        measured: np.ndarray | None = None,
    ) -> None:
        coeffs, gains = coefficients(config)
        self.kernel = step_kernel(num_envs)
        self.dims = (num_envs, config.n_vessels, obs_low.shape[0])
        self.model = (
            LEVEL_CODES[config.action_level],
            coeffs,
            gains,
            config.paper_as_printed,
            config.dt,
            config.substeps,
            config.tau_u_max,
            config.tau_r_max,
            np.array(config.current.coefficients),
        )
        self.geometry = (np.ascontiguousarray(config.formation), slot_index, slot_mask)
        self.config = config
        w = config.reward  # the reward's weights, scales and terminal rate
        self.limits = (
            obs_low,
            obs_high,
            np.array([*w.tracking_weights, w.effort]),
            np.array([*w.tracking_sigmas, *w.fine_shares, w.fine_scale]),
        )
        ends = (np.array(config.workspace), config.safety_distance, config.max_speed, config.max_yaw_rate)
        self.tail = (w.terminal_rate, *ends)
        self.channel, self.sensor_noise = channel, sensor_noise
        if channel is None:  # placeholders of the same types: one compiled kernel serves both cases
            ideal = [(math.inf, np.eye(config.n_vessels))]
            placeholder = channel_module.LinkChannel(
                channel_module.ChannelConfig(), config.n_vessels, config.dt, ideal, max_steps=1, num_envs=1
            )
            self.chan = channel_args(config, placeholder, None, None, slot_index, obs_low, obs_high)
        else:
            self.chan = channel_args(config, channel, sensor_noise, measured, slot_index, obs_low, obs_high)
        self._scratch = (np.empty((num_envs, config.n_vessels)), np.empty((num_envs, config.n_vessels)))
        self.path = (
            not config.straight,
            *config.path.segment_arrays,
        )
        self.path_tail = (
            float(config.corridor) if not config.straight else math.inf,
            rules.LOOKAHEAD,
            np.zeros((num_envs, config.n_vessels, 4)),
        )

    @property
    def sent_track(self) -> tuple[np.ndarray, np.ndarray]:
        """``(θ, ẋ)``, each ``(B, N)``, of the last ``run``'s control instant as the channel saw them (of the
        measurement, ẋ over ground): with a channel, what each vessel broadcast or would have."""
        return self._scratch

    def run(
        self,
        state: np.ndarray,
        commands: np.ndarray,
        last_u_c: np.ndarray,
        time0: np.ndarray,
        steer_dy: np.ndarray,
        time1: np.ndarray,
        steps: np.ndarray,
        actions: np.ndarray,
        restart: np.ndarray,
        initial: np.ndarray,
        arc: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Advance ``state`` ``(B, N, 6)`` in place by one control period (and the channel, if any).

        Args:
            commands: ``(B, N, 2)`` physical commands: (τ_u, τ_r) | (u_c, ψ_d) | (u_c, 0).
            last_u_c: ``(B, N)`` the previous period's u_c (first-order hold).
            time0, time1: ``(B,)`` time at the start and at the end of the period [s].
            steer_dy: ``(B, N)`` the path offset the built-in LOS steers to.
            steps: ``(B,)`` control periods since reset at the end of the period.
            actions: ``(B, N, A)`` the clipped normalized actions (effort term).
            restart: ``(B,)`` formations that start anew from ``initial`` ``(B, N, 6)``
                instead of stepping (zero reward, no flags; ``time1`` and
                ``steps`` are 0 for them; their channel is reset first).
            arc: ``(B, N)`` the vessels' projections on a curved path (the restarting
                formations' already those of ``initial``), updated in place.

        Returns:
            ``(observation (B, N, D) float32, components (6, B, N), reward (B, N),
            flags (B, 2): collision, out_of_bounds)``.
        """
        b, n, dim = self.dims
        cfg = self.config
        # the kernel writes the own part and the n − 1 vessels' slots; padding slots (observation_slots) stay 0
        obs = (
            np.empty((b, n, dim), dtype=np.float32)
            if dim == OWN_SIZE + SLOT_SIZE * (n - 1)
            else np.zeros((b, n, dim), dtype=np.float32)
        )
        comps = np.empty((6, b, n))
        flags = np.empty((b, 2), dtype=np.bool_)
        reward = np.empty((b, n))
        if self.channel is not None:
            uniforms = self.channel.uniforms
            uniforms.refill()  # an unread row for every formation ...
            if self.channel.channel.burst is not None and restart.any():
                uniforms.refill(np.flatnonzero(restart), rows=2)  # ... and one more where the chains restart
            if self.sensor_noise is not None:
                self.sensor_noise.normals.refill()
        self.kernel(
            state,
            commands,
            last_u_c,
            *self.model,
            time0,
            steer_dy,
            *self.geometry,
            np.asarray(cfg.u_d.value(time1), dtype=float),
            np.asarray(cfg.u_d.rate(time1), dtype=float),
            cfg.horizon - time1,
            *self.limits,
            actions,
            *self.tail,
            obs,
            comps,
            reward,
            flags,
            *self._scratch,
            restart,
            initial,
            time1,
            steps,
            self.channel is not None,
            self.chan,
            *self.path,
            arc,
            *self.path_tail,
        )
        return obs, comps, reward, flags


def channel_args(
    config: Any,
    channel: Any,
    sensor_noise: Any,
    measured: np.ndarray | None,
    slot_index: np.ndarray,
    obs_low: np.ndarray,
    obs_high: np.ndarray,
) -> tuple[Any, ...]:
    """The channel's part of the kernel's arguments: constants, and the state arrays it updates in place."""
    ch = channel.channel
    n = channel.n
    burst = ch.burst
    if sensor_noise is not None:
        normals = sensor_noise.normals
        noise = (True, normals.buffer, normals.pos, sensor_noise.scale, measured)
    else:
        noise = (False, np.empty((1, 1, 6 * n)), np.zeros(1, dtype=np.int64), np.zeros(6), np.empty((1, n, 6)))
    rule = (
        channel.tdma,
        int(channel.every),
        ch.failure_rate > 0 or ch.recovery_rate > 0,
        float(channel.p_fail),
        float(channel.p_recover),
        burst is not None,
        0.0 if burst is None else float(burst.p_good_to_bad),
        0.0 if burst is None else float(burst.p_bad_to_good),
        0.0 if burst is None else float(burst.p_bad),
        0.0 if burst is None else float(burst.loss_good),
        0.0 if burst is None else float(burst.loss_bad),
        float(ch.latency),
        float(ch.jitter),
        ch.max_delay > 0,
        int(channel.max_delay_steps),
        int(channel.depth),
        float(channel.dt),
        float(ch.range),
        math.isfinite(ch.range),
    )
    return (
        noise,
        (not config.current.is_zero, np.array(config.current.coefficients, dtype=float)),
        rule,
        np.ascontiguousarray(channel.graphs),
        np.asarray(channel.ends, dtype=float),
        np.ascontiguousarray(np.broadcast_to(np.asarray(channel.loss_matrix, dtype=float), (n, n))),
        channel.uniforms.buffer,
        channel.uniforms.pos,
        (
            channel.up,
            channel.has_message,
            channel.held_theta,
            channel.held_xdot,
            channel.held_time,
            channel.failed,
            channel.bad,
            channel.transmitted,
        ),
        (channel.pend_valid, channel.pend_theta, channel.pend_xdot, channel.pend_time, channel.next_arrival),
        (slot_index, obs_low, obs_high),
        (
            (
                int(channel.mode),
                float(channel.threshold),
                int(channel.min_steps),
                int(channel.heartbeat_steps),
                ch.has_budget,
                float(channel.refill),
                float(ch.bucket),
                float(ch.message_bits),
            ),
            channel.wants,
            channel.sent_theta,
            channel.sent_xdot,
            channel.sent_time,
            channel.sent_step,
            channel.tokens,
            channel.counts,
        ),
    )
