"""The multibody model the solver computes with: an :class:`OsimModel` converted to pinocchio.

Every moving axis of every OpenSim joint becomes one 1-DoF pinocchio joint
(``JointModelRevoluteUnaligned`` or ``JointModelPrismaticUnaligned``); constant axes and
offset frames become fixed placements. The expanded joint values are exact functions
of the OpenSim coordinates (:mod:`solver.model.coupling`), so spline-driven knee
translations, the patella coupler and locked coordinates are reproduced exactly.

The public API speaks OpenSim coordinates in CoordinateSet order: ``q (n,)`` or
``(T, n)`` in rad (rotational, coupled) or m (translational). Frames: the OpenSim
ground frame (Y up). Rigid-body algorithms (RNEA, CRBA, Jacobians) are pinocchio's;
the batched forward kinematics used for whole trials composes the same placements in
numpy over all frames at once (checked against pinocchio in tests/model).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from solver.errors import OsimModelError
from solver.model.coupling import CoordinateMap
from solver.model.functions import Linear
from solver.model.osim import ROTATIONAL, TRANSLATIONAL, OsimModel

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def _skew(a: FloatArray) -> FloatArray:
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def _rotation_about(axis: FloatArray, angle: float) -> FloatArray:
    k = _skew(axis)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


@dataclass(frozen=True)
class ExternalWrench:
    """A wrench applied to a body, in the ground frame, for every frame of a trial.

    Attributes
    ----------
    body
        Name of the body the wrench acts on (e.g. ``calcn_r``).
    force
        ``(T, 3)`` force on the body, N, ground frame.
    point
        ``(T, 3)`` point of application (e.g. the centre of pressure), m, ground frame.
    moment
        ``(T, 3)`` free couple added to the force (e.g. the plate's free moment), N·m.
    """

    body: str
    force: FloatArray
    point: FloatArray
    moment: FloatArray


@dataclass(frozen=True)
class DynamicsResult:
    """Inverse dynamics of a trial.

    Attributes
    ----------
    tau
        ``(T, n)`` generalized forces on the OpenSim coordinates (N·m rotational, N
        translational); zero on dependent (coupled) coordinates when constrained.
    root_force
        ``(T, 3)`` residual force the root joint must supply, N, ground frame.
    root_moment
        ``(T, 3)`` residual moment the root joint must supply, about the root body's
        origin (the pelvis origin), N·m, ground frame.
    """

    tau: FloatArray
    root_force: FloatArray
    root_moment: FloatArray


def _frames_first(a: FloatArray, block: int = 256) -> FloatArray:
    """``(..., T)`` frames-last array as a C-contiguous ``(T, ...)`` copy.

    Copied ``block`` leading rows at a time: numpy's one-pass transposed copy reads each
    output row across all T frames and ran 3-8x slower for 500-3000 frames (T = 500 is a
    4000-byte stride, the worst). Values are copied, not computed: the result equals
    ``np.ascontiguousarray(np.moveaxis(a, -1, 0))``.
    """
    t = a.shape[-1]
    flat = a.reshape(-1, t)
    out = np.empty((t, flat.shape[0]), dtype=a.dtype)
    for s in range(0, flat.shape[0], block):
        out[:, s : s + block] = flat[s : s + block].T
    return out.reshape((t, *a.shape[:-1]))


class Skeleton:
    """Pinocchio model of an OpenSim model, with OpenSim coordinates as its interface.

    Parameters
    ----------
    osim
        The parsed (possibly scaled) model.

    Raises
    ------
    OsimModelError
        If the model has no root joint to ground.
    """

    def __init__(self, osim: OsimModel) -> None:
        self.osim = osim
        self.coordinate_names: tuple[str, ...] = osim.coordinate_names
        self.n = len(self.coordinate_names)
        cidx = {c: i for i, c in enumerate(self.coordinate_names)}
        self._cidx = cidx
        self.motion_types = tuple(c.motion_type for c in osim.coordinates)
        self.is_rotational = np.array([m == ROTATIONAL for m in self.motion_types])
        self.is_translational = np.array([m == TRANSLATIONAL for m in self.motion_types])
        self.ranges = np.array([c.range for c in osim.coordinates], dtype=float).reshape(-1, 2)
        self.defaults = np.array([c.default_value for c in osim.coordinates], dtype=float)
        self.locked = np.array([c.locked for c in osim.coordinates], dtype=bool)
        self.clamped = np.array([c.clamped for c in osim.coordinates], dtype=bool)
        self.body_names: tuple[str, ...] = osim.body_names
        self._build(osim, cidx)
        self.cmap = CoordinateMap(
            self.n,
            self._dof_coord,
            self._dof_func,
            [(cidx[c.dependent], cidx[c.independent], c.function, c.scale_factor) for c in osim.couplers],
        )
        self.is_independent = self.cmap.is_independent
        self.full_turn = self._full_turn_coordinates()
        self.set_markers(osim)

    # ------------------------------------------------------------------ building

    def _build(self, osim: OsimModel, cidx: dict[str, int]) -> None:
        model = pin.Model()
        model.name = osim.name
        model.gravity.linear = np.asarray(osim.gravity, dtype=float)
        # placement of each body frame in the frame of the pinocchio joint carrying it
        body_joint: dict[str, int] = {"ground": 0}
        body_place: dict[str, pin.SE3] = {"ground": pin.SE3.Identity()}
        self._dof_coord: list[int] = []
        self._dof_func = []
        self._jtype: list[int] = [0]  # 0 revolute, 1 prismatic (index 0 = universe)
        self._jaxis: list[FloatArray] = [np.zeros(3)]
        self.dof_names: list[str] = []
        root_first_dof: int | None = None
        # per joint: (joint, [(axis, pin dof index or None, constant angle)] for rotation1..3)
        self.joint_rotations: list[tuple[object, list[tuple[FloatArray, int | None, float]]]] = []
        for joint in osim.joints:
            parent = joint.parent
            pending = body_place[parent.body] * pin.SE3(parent.rotation(), np.array(parent.translation))
            jid = body_joint[parent.body]
            trans = [a for a in joint.axes if a.kind == "translation"]
            rots = [a for a in joint.axes if a.kind == "rotation"]
            const_t = sum(
                (np.array(a.axis) * float(a.function.value(0.0)) for a in trans if a.coordinate is None),
                np.zeros(3),
            )
            pending = pending * pin.SE3(np.eye(3), const_t)
            first_dof = None
            rot_info: list[tuple[FloatArray, int | None, float]] = []
            for a in trans + rots:
                if a.kind == "rotation":
                    rot_info.append(
                        (np.array(a.axis), None if a.coordinate is None else len(self.dof_names), float(a.function.value(0.0)))
                    )
                if a.coordinate is None:
                    if a.kind == "rotation":
                        pending = pending * pin.SE3(_rotation_about(np.array(a.axis), float(a.function.value(0.0))), np.zeros(3))
                    continue
                axis = np.array(a.axis, dtype=float)
                jm = (
                    pin.JointModelRevoluteUnaligned(axis)
                    if a.kind == "rotation"
                    else pin.JointModelPrismaticUnaligned(axis)
                )
                name = f"{joint.name}/{a.coordinate}/{a.kind}{len(self.dof_names)}"
                jid = model.addJoint(jid, jm, pending, name)
                pending = pin.SE3.Identity()
                self._jtype.append(0 if a.kind == "rotation" else 1)
                self._jaxis.append(axis)
                self._dof_coord.append(cidx[a.coordinate])
                self._dof_func.append(a.function)
                self.dof_names.append(name)
                if first_dof is None:
                    first_dof = jid
            self.joint_rotations.append((joint, rot_info))
            child = joint.child
            child_off = pin.SE3(child.rotation(), np.array(child.translation))
            body_joint[child.body] = jid
            body_place[child.body] = pending * child_off.inverse()
            if parent.body == "ground" and first_dof is not None and root_first_dof is None:
                root_first_dof = first_dof
                self.root_body = child.body
        for b in osim.bodies:
            if b.name not in body_joint:
                raise OsimModelError(f"body {b.name} has no joint", path=osim.source)
            inertia = pin.Inertia(b.mass, np.array(b.com), np.array(b.inertia))
            model.appendBodyToJoint(body_joint[b.name], inertia, body_place[b.name])
            model.addBodyFrame(b.name, body_joint[b.name], body_place[b.name], 0)
        if root_first_dof is None:
            raise OsimModelError("no joint connects a body to ground with moving coordinates", path=osim.source)
        self.model = model
        self._data: pin.Data | None = None  # created on first use (:attr:`data`): ~3 ms each
        self.root_joint = root_first_dof
        self.nv = model.nv
        self.body_joint = np.array([body_joint[b] for b in self.body_names], dtype=np.intp)
        self.body_rot = np.array([body_place[b].rotation for b in self.body_names]).reshape(-1, 3, 3)
        self.body_pos = np.array([body_place[b].translation for b in self.body_names]).reshape(-1, 3)
        self.body_mass = np.array([b.mass for b in osim.bodies])
        self.body_com = np.array([b.com for b in osim.bodies]).reshape(-1, 3)
        self._body_index = {b: i for i, b in enumerate(self.body_names)}
        self._body_joint_map = body_joint
        self._body_place_map = body_place
        nj = model.njoints
        self._parents = np.array(model.parents, dtype=np.intp)
        self._place_R = np.array([model.jointPlacements[j].rotation for j in range(nj)])
        self._place_p = np.array([model.jointPlacements[j].translation for j in range(nj)])
        self._idx_v = np.array([model.idx_vs[j] for j in range(nj)], dtype=np.intp)
        self._identity_r = (self._place_R == np.eye(3)).all(axis=(1, 2)).tolist()  # exactly, per joint
        self._zero_p = (self._place_p == 0.0).all(axis=1).tolist()
        self._axis_in_parent = [r @ a for r, a in zip(self._place_R, self._jaxis)]
        k = np.array([_skew(a) for a in self._jaxis])
        self._PK = np.einsum("jab,jbc->jac", self._place_R, k)  # placement @ skew(axis)
        self._PK2 = np.einsum("jab,jbc->jac", self._PK, k)
        support = np.zeros((nj, self.nv), dtype=bool)
        for j in range(1, nj):
            for s in model.supports[j]:
                if s > 0:
                    support[j, model.idx_vs[s]] = True
        self._support = support
        self._chains: dict[bytes, list[int]] = {}  # joint subsets -> their chains (:meth:`_chain`)

    def _full_turn_coordinates(self) -> NDArray[np.bool_]:
        """``(n,)`` True for the coordinates whose change by a full turn (2 pi rad) moves no
        body: rotational and independent, no coupler's input, and every DoF they drive a
        rotation by plus or minus the coordinate (a linear function of slope +-1), as a
        CustomJoint's rotation axes and a PinJoint's angle are. Such a coordinate's value is
        only defined up to full turns by the markers (see
        :func:`solver.kinematics.ik.solve_trajectory`)."""
        out = self.is_rotational & self.is_independent
        out[self.cmap.independent_of] = False
        for j, (c, f) in enumerate(zip(self._dof_coord, self._dof_func), start=1):
            if self._jtype[j] != 0 or not isinstance(f, Linear) or abs(f.slope) != 1.0:
                out[c] = False
        return out

    def set_markers(self, osim: OsimModel) -> None:
        """(Re)load the marker set from ``osim`` (same bodies): names, bodies, locations."""
        names, joints, local, bodies = [], [], [], []
        for m in osim.markers:
            if m.body == "ground":
                jid, place = 0, pin.SE3.Identity()
            else:
                jid, place = self._body_joint_map[m.body], self._body_place_map[m.body]
            names.append(m.name)
            bodies.append(m.body)
            joints.append(jid)
            local.append(place.act(np.array(m.location, dtype=float)))
        self.marker_names: tuple[str, ...] = tuple(names)
        self.marker_bodies: tuple[str, ...] = tuple(bodies)
        self.marker_joint = np.array(joints, dtype=np.intp)
        self.marker_in_joint = np.array(local, dtype=float).reshape(-1, 3)
        self._marker_index = {n: i for i, n in enumerate(names)}
        uniq, inv = np.unique(self.marker_joint, return_inverse=True)
        self._marker_joints_uniq = [int(j) for j in uniq]
        self._marker_slot = inv.astype(np.intp).reshape(-1)
        # (nv, U * n) 0/1: DoF k moves the joint of slot u and drives coordinate root(k); with
        # the coupling Jacobian's nonzeros w (nv,), (J_world * w) @ it gives every marker
        # joint's world Jacobian in the coordinates at once (see marker_jacobian)
        selection = np.zeros((self.nv, uniq.size, self.n))
        for u, j in enumerate(self._marker_joints_uniq):
            selection[np.arange(self.nv), u, self.cmap.dof_root] = self._support[j]
        self._marker_selection = selection.reshape(self.nv, -1)

    @property
    def data(self) -> pin.Data:
        """The pinocchio data (work buffers) of :attr:`model`, created on first use: many
        skeletons (the scale fit's steps, the batched numpy kinematics) never need it."""
        if self._data is None:
            self._data = self.model.createData()
        return self._data

    # ------------------------------------------------------------------ lookups

    def coordinate_index(self, name: str) -> int:
        """Index of OpenSim coordinate ``name``; raises ``KeyError`` naming it."""
        try:
            return self._cidx[name]
        except KeyError:
            raise KeyError(f"model {self.osim.name} has no coordinate {name!r}") from None

    def marker_index(self, names: list[str] | tuple[str, ...]) -> IntArray:
        """``(M,)`` indices of the M named model markers (in :attr:`marker_names`); raises
        ``KeyError`` naming a missing one."""
        try:
            return np.array([self._marker_index[n] for n in names], dtype=np.intp)
        except KeyError as exc:
            raise KeyError(f"model {self.osim.name} has no marker {exc.args[0]!r}") from None

    def body_index(self, name: str) -> int:
        """Index of body ``name`` in :attr:`body_names`; raises ``KeyError`` naming it."""
        try:
            return self._body_index[name]
        except KeyError:
            raise KeyError(f"model {self.osim.name} has no body {name!r}") from None

    @property
    def total_mass(self) -> float:
        """Total mass, kg."""
        return float(self.body_mass.sum())

    def neutral(self) -> FloatArray:
        """``(n,)`` default coordinate values with couplers applied."""
        return self.cmap.complete(self.defaults)

    # ------------------------------------------------------------------ kinematics (batched)

    def _joint_poses_soa(self, q: FloatArray, joints: IntArray | None = None) -> tuple[FloatArray, FloatArray]:
        """Joint placements with frames last: ``(nj, 3, 3, T)`` and ``(nj, 3, T)``.

        Frames-last ("structure of arrays") keeps each 3x3 product a handful of long
        vectorized operations, which is what makes batched kinematics cheap in numpy.
        With ``joints`` (pinocchio joint indices), only those joints and their ancestors
        are computed (the same arithmetic, so the same values); the other entries are
        left uninitialized.
        """
        q2 = np.atleast_2d(np.asarray(q, dtype=float))
        qp, _, _ = self.cmap.expand(q2)
        t = q2.shape[0]
        nj = self._parents.size
        rot = np.empty((nj, 3, 3, t))
        pos = np.empty((nj, 3, t))
        rot[0] = np.eye(3)[:, :, None]
        pos[0] = 0.0
        for j in range(1, nj) if joints is None else self._chain(joints):
            x = qp[:, self._idx_v[j]]
            place_r, place_p = self._place_R[j], self._place_p[j]
            if self._jtype[j] == 0:
                r_loc = self._PK[j][:, :, None] * np.sin(x) + self._PK2[j][:, :, None] * (1.0 - np.cos(x))
                r_loc += place_r[:, :, None]
                p_loc = None if self._zero_p[j] else place_p[:, None]
            else:
                r_loc = None if self._identity_r[j] else place_r[:, :, None]
                p_loc = place_p[:, None] + self._axis_in_parent[j][:, None] * x
            par = self._parents[j]
            r_par, p_par = rot[par], pos[par]
            rot[j] = r_par if r_loc is None else np.einsum("ijt,jkt->ikt", r_par, r_loc)
            pos[j] = p_par if p_loc is None else p_par + np.einsum("ijt,jt->it", r_par, np.broadcast_to(p_loc, (3, t)))
        return rot, pos

    def _chain(self, joints: IntArray) -> list[int]:
        """The joints ``joints`` and all their ancestors except the universe, parents first."""
        asked = np.unique(joints)
        key = asked.tobytes()
        chain = self._chains.get(key)
        if chain is None:
            need = np.zeros(self._parents.size, dtype=bool)
            for j in asked.tolist():
                while j > 0 and not need[j]:
                    need[j] = True
                    j = int(self._parents[j])
            chain = np.flatnonzero(need).tolist()  # pinocchio numbers a parent before its children
            self._chains[key] = chain
        return chain

    def joint_poses(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """World placement of every pinocchio joint frame for many frames.

        Parameters
        ----------
        q
            ``(T, n)`` or ``(n,)`` coordinates.

        Returns
        -------
        R, p
            ``(T, njoints, 3, 3)`` rotations and ``(T, njoints, 3)`` origins, ground frame
            (index 0 is the universe).
        """
        rot, pos = self._joint_poses_soa(q)
        return rot.transpose(3, 0, 1, 2), pos.transpose(2, 0, 1)

    def body_poses(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """World pose of every body frame.

        Parameters
        ----------
        q
            ``(T, n)`` or ``(n,)`` coordinates.

        Returns
        -------
        R, p
            ``(T, B, 3, 3)`` body rotations (columns: body axes in ground) and ``(T, B, 3)``
            body origins, m, in :attr:`body_names` order.
        """
        rot, pos = self._joint_poses_soa(q)
        rj, pj = rot[self.body_joint], pos[self.body_joint]  # (B, 3, 3, T), (B, 3, T)
        r_body = np.einsum("bijt,bjk->tbik", rj, self.body_rot)
        p_body = pj.transpose(2, 0, 1) + np.einsum("bijt,bj->tbi", rj, self.body_pos)
        return r_body, p_body

    def marker_positions(self, q: FloatArray, markers: IntArray | None = None) -> FloatArray:
        """Model marker positions in the ground frame.

        Parameters
        ----------
        q
            ``(T, n)`` or ``(n,)`` coordinates.
        markers
            Indices into :attr:`marker_names` (default: all).

        Returns
        -------
        ``(T, M, 3)`` positions, m.
        """
        idx = np.arange(len(self.marker_names)) if markers is None else np.asarray(markers)
        j = self.marker_joint[idx]
        rot, pos = self._joint_poses_soa(q, j)
        out = pos[j] + np.einsum("mijt,mj->mit", rot[j], self.marker_in_joint[idx])
        return out.transpose(2, 0, 1)

    def center_of_mass(self, q: FloatArray) -> FloatArray:
        """``(T, 3)`` whole-body centre of mass in the ground frame, m."""
        rb, pb = self.body_poses(q)
        com = pb + np.einsum("tbij,bj->tbi", rb, self.body_com)
        return np.einsum("tbi,b->ti", com, self.body_mass) / self.body_mass.sum()

    # ------------------------------------------------------------------ single-frame pinocchio

    def expand(self, q: FloatArray) -> FloatArray:
        """``(nv,)`` or ``(T, nv)`` pinocchio configuration for OpenSim coordinates q."""
        return self.cmap.expand(np.asarray(q, dtype=float))[0]

    def marker_jacobian(self, q: FloatArray, markers: IntArray) -> tuple[FloatArray, FloatArray]:
        """Marker positions and their Jacobian with respect to the OpenSim coordinates.

        Parameters
        ----------
        q
            ``(n,)`` coordinates of one frame.
        markers
            ``(M,)`` indices into :attr:`marker_names`.

        Returns
        -------
        positions
            ``(M, 3)`` ground frame, m.
        jacobian
            ``(M, 3, n)`` d position / d q; columns of dependent (coupled) coordinates are
            zero, their effect is included in the independent coordinate's column.
        """
        qp, w = self.cmap.expand_with_derivatives(np.asarray(q, dtype=float))
        data = self.data
        pin.computeJointJacobians(self.model, data, qp)
        # data.J (6, nv): world-frame motion of each DoF axis at the ground origin; per marker
        # joint u (the DoFs that move it, in the coordinates): A_u = J[:, dofs(u)] C[dofs(u)]
        n_uniq = len(self._marker_joints_uniq)
        a = ((data.J * w) @ self._marker_selection).reshape(6, n_uniq, self.n)
        slot = self._marker_slot[markers]
        placements = data.oMi.tolist()
        hom = np.array([placements[j].homogeneous for j in self._marker_joints_uniq])[slot]  # (M, 4, 4)
        local = self.marker_in_joint[markers]
        pm = (hom[:, :3, :3] * local[:, None, :]).sum(axis=2) + hom[:, :3, 3]
        a = a[:, slot].transpose(1, 0, 2)  # (M, 6, n): [linear at the origin; angular]
        skew = np.zeros((slot.size, 3, 3))  # point velocity v = v0 + w x p = v0 - [p]x w
        skew[:, 0, 1], skew[:, 0, 2] = -pm[:, 2], pm[:, 1]
        skew[:, 1, 0], skew[:, 1, 2] = pm[:, 2], -pm[:, 0]
        skew[:, 2, 0], skew[:, 2, 1] = -pm[:, 1], pm[:, 0]
        return pm, a[:, :3] - skew @ a[:, 3:]

    def marker_jacobians(
        self, q: FloatArray, markers: IntArray, columns: IntArray | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """:meth:`marker_jacobian` for many frames at once (batched forward kinematics in numpy).

        The DoF columns are the ones pinocchio's world-frame joint Jacobian gives: a revolute
        DoF with world axis w through the joint origin o moves a point p at w x (p - o), a
        prismatic one at w; they are mapped to the OpenSim coordinates with the coupling
        Jacobian. Equal to the per-frame method to round-off (checked in tests/model).

        Parameters
        ----------
        q
            ``(T, n)`` or ``(n,)`` coordinates (rad or m).
        markers
            ``(M,)`` indices into :attr:`marker_names`.
        columns
            ``(k,)`` coordinate indices whose Jacobian columns to return, in that order
            (default: all n).

        Returns
        -------
        positions
            ``(T, M, 3)`` ground frame, m.
        jacobian
            ``(T, M, 3, k)`` d position / d q (m per rad or m/m); columns of dependent
            (coupled) coordinates are zero, their effect is in the independent coordinate's.
            C-contiguous (built frames-last, then copied by :func:`_frames_first`: a
            frames-last view made each frame's products in the dynamics fit stride across
            frames, 7x slower for J^T J on a 500-frame trial).
        """
        q2 = np.atleast_2d(np.asarray(q, dtype=float))
        markers = np.asarray(markers, dtype=np.intp)
        rot, pos = self._joint_poses_soa(q2)  # (nj, 3, 3, T), (nj, 3, T)
        mj = self.marker_joint[markers]
        pm = pos[mj] + np.einsum("mijt,mj->mit", rot[mj], self.marker_in_joint[markers])  # (M, 3, T)
        vals, cols = self.cmap.jacobian_batch(q2)  # (T, nv), (nv,)
        out_col = np.arange(self.n) if columns is None else np.full(self.n, -1)
        if columns is not None:
            out_col[np.asarray(columns, dtype=np.intp)] = np.arange(len(columns))
        t, m = q2.shape[0], markers.size
        jac = np.zeros((m, 3, self.n if columns is None else len(columns), t))
        support = self._support[mj]  # (M, nv)
        for j in range(1, self._parents.size):
            dof = self._idx_v[j]
            moved = np.flatnonzero(support[:, dof])
            if moved.size == 0 or out_col[cols[dof]] < 0:
                continue
            w = np.einsum("ijt,j->it", rot[j], self._jaxis[j])  # (3, T) world axis
            if self._jtype[j] == 0:
                arm = pm[moved] - pos[j][None]  # (k, 3, T)
                col = np.stack(
                    [w[1] * arm[:, 2] - w[2] * arm[:, 1], w[2] * arm[:, 0] - w[0] * arm[:, 2], w[0] * arm[:, 1] - w[1] * arm[:, 0]],
                    axis=1,
                )
            else:
                col = np.broadcast_to(w[None], (moved.size, 3, t))
            jac[moved, :, out_col[cols[dof]]] += col * vals[:, dof]
        return pm.transpose(2, 0, 1), _frames_first(jac)

    # ------------------------------------------------------------------ dynamics

    def inverse_dynamics(
        self,
        q: FloatArray,
        qd: FloatArray,
        qdd: FloatArray,
        wrenches: list[ExternalWrench] | tuple[ExternalWrench, ...] = (),
        *,
        constrained: bool = True,
        opensim_compatible: bool = False,
    ) -> DynamicsResult:
        """Generalized forces that produce the motion under gravity and external wrenches.

        Parameters
        ----------
        q, qd, qdd
            ``(T, n)`` coordinates and their time derivatives (rad, rad/s, rad/s² or m...).
        wrenches
            External loads in the ground frame (e.g. ground reaction forces).
        constrained
            True (default): coupler constraints hold; dependent coordinates follow their
            independent one and their force is projected onto it. False: every
            coordinate is independent (OpenSim's ``calcResidualForceIgnoringConstraints``).
        opensim_compatible
            Reproduce Simbody's velocity-dependent term of function-based (Custom)
            joints, which is inexact when two rotations of one joint are driven by the
            same coordinate (the walker knee); see :mod:`solver.model.opensim_compat`.
            Off by default: the default result is the exact one.

        Returns
        -------
        DynamicsResult
            Generalized forces and the root residual wrench per frame.
        """
        q2, qd2, qdd2 = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (q, qd, qdd))
        t = q2.shape[0]
        qp, vp, ap = self.cmap.expand(q2, qd2, qdd2, constrained=constrained)
        if opensim_compatible:
            from solver.model.opensim_compat import simbody_hdot_error

            ap = ap + simbody_hdot_error(self, qp, vp)
        rot, pos = self._joint_poses_soa(q2)  # (nj, 3, 3, T), (nj, 3, T)
        local = {j: self._to_joint_frame(w, rot[j], pos[j]) for j, w in self._world_wrenches(wrenches, t).items()}
        model, data = self.model, self.data
        tau_pin = np.empty((t, self.nv))
        root = np.empty((t, 6))
        fext = [pin.Force.Zero() for _ in range(model.njoints)]
        rj = self.root_joint
        for k in range(t):
            if local:
                for j, w in local.items():
                    fext[j] = pin.Force(w[k])
                tau_pin[k] = pin.rnea(model, data, qp[k], vp[k], ap[k], fext)
            else:
                tau_pin[k] = pin.rnea(model, data, qp[k], vp[k], ap[k])
            root[k] = data.f[rj].vector  # [linear, angular] in the root joint's frame
        force = np.einsum("ijt,tj->ti", rot[rj], root[:, :3])
        moment_at_joint = np.einsum("ijt,tj->ti", rot[rj], root[:, 3:])
        bj = self._body_joint_map[self.root_body]
        origin = pos[bj] + np.einsum("ijt,j->it", rot[bj], self._body_place_map[self.root_body].translation)
        moment = moment_at_joint + np.cross(pos[rj].T - origin.T, force)
        tau = self.cmap.project(q2, tau_pin, constrained=constrained)
        return DynamicsResult(tau=tau, root_force=force, root_moment=moment)

    @staticmethod
    def _to_joint_frame(wrench: FloatArray, rot: FloatArray, pos: FloatArray) -> FloatArray:
        """(T, 6) [force, moment about the ground origin] -> the same wrench in a joint frame
        with rotation ``rot`` (3, 3, T) and origin ``pos`` (3, T), moment about that origin."""
        f, m = wrench[:, :3], wrench[:, 3:]
        m_joint = m - np.cross(pos.T, f)
        return np.concatenate(
            [np.einsum("jit,tj->ti", rot, f), np.einsum("jit,tj->ti", rot, m_joint)], axis=1
        )

    def _world_wrenches(self, wrenches: list[ExternalWrench] | tuple[ExternalWrench, ...], t: int) -> dict[int, FloatArray]:
        """Sum the wrenches per pinocchio joint as (T, 6) [force, moment about the ground origin]."""
        out: dict[int, FloatArray] = {}
        for w in wrenches:
            if w.body not in self._body_joint_map:
                raise KeyError(f"external wrench on unknown body {w.body!r}")
            j = self._body_joint_map[w.body]
            f = np.asarray(w.force, dtype=float).reshape(t, 3)
            p = np.asarray(w.point, dtype=float).reshape(t, 3)
            m = np.asarray(w.moment, dtype=float).reshape(t, 3)
            wr = np.concatenate([f, np.cross(p, f) + m], axis=1)
            out[j] = out.get(j, 0.0) + wr
        return {j: np.nan_to_num(w) for j, w in out.items()}

    def mass_matrix(self, q: FloatArray, *, constrained: bool = True) -> FloatArray:
        """``(n, n)`` joint-space mass matrix C^T M_pin C in OpenSim coordinates (one frame)."""
        qp, _, _ = self.cmap.expand(np.asarray(q, dtype=float), constrained=constrained)
        mp = pin.crba(self.model, self.data, qp)
        mp = np.triu(mp) + np.triu(mp, 1).T
        cmat = self.cmap.jacobian(np.asarray(q, dtype=float), constrained=constrained)
        return cmat.T @ mp @ cmat

    def root_transform_axes(self) -> tuple[int, ...]:
        """Indices of the root joint's coordinates (the six residual coordinates)."""
        root_joint = self.osim.joints[0]
        return tuple(self._cidx[c] for c in root_joint.coordinates)

