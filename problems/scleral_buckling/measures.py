"""What the eye reports beyond its terms: its optics (axial length, the central cornea's
curvature and power, the refraction's change from the eye before surgery) and the
detached retina's gap to the choroid (the tear's closure)."""

from __future__ import annotations

import math

import dolfinx
import numpy as np
from mpi4py import MPI

from eyemech.problems.solid.probes import NodeProbe, SurfacePairing, facet_nodes
from eyemech.problems.solve.scalars import assemble_scalar

# refraction from the geometry: diopters per mm of axial length (Gullstrand's schematic
# eye, emmetropic: ≈ 2.7 D/mm) and the keratometric index that turns the anterior
# corneal radius into power, K = (n_k − 1)/R (n_k = 1.3375, the keratometers' convention)
DIOPTRES_PER_MM = 2.7
KERATOMETRIC_INDEX = 1.3375
KERATOMETRY_ZONE = 3.0  # mm from the axis: the central cornea a keratometer reads


class Optics:
    """Axial length (corneal apex to the retina's posterior pole) and the central cornea's
    radius of curvature: a sphere fitted (least squares) to the deformed anterior corneal
    nodes within the keratometry zone, with its keratometric power (n_k − 1)/R. Changes
    are read from the eye before surgery (:meth:`record_preoperative`)."""

    def __init__(self, body):
        self.body = body
        V, geo, eye = body.u.function_space, body.geometry, body.eye
        cornea = facet_nodes(V, eye.facets("cornea_outer"))
        inner = facet_nodes(V, eye.facets("retina_inner"))
        self.apex = NodeProbe(V, np.array([[0.0, 0.0, geo.cornea_center + geo.cornea_radius]]), cornea)
        self.pole = NodeProbe(V, np.array([[0.0, 0.0, -geo.sclera_radius]]), inner)
        # the central cornea a keratometer reads (ρ ≤ 3 mm; at least 4 nodes)
        X = V.tabulate_dof_coordinates()
        mine = cornea[cornea < V.dofmap.index_map.size_local]
        rho = np.hypot(X[mine, 0], X[mine, 1])
        for zone in (KERATOMETRY_ZONE, 4.0, 5.0):
            central = mine[rho <= zone]
            if body.comm.allreduce(len(central), op=MPI.SUM) >= 4:
                break
        self.central_cornea = central.astype(np.int32)
        self.preoperative: dict[str, float] = {}  # the eye before surgery

    def read(self) -> dict:
        """Axial length, corneal radius and power now (collective)."""
        u = self.body.u
        apex, pole = self.apex.positions(u)[0], self.pole.positions(u)[0]
        V = u.function_space
        x = V.tabulate_dof_coordinates()[self.central_cornea] \
            + u.x.array.reshape(-1, 3)[self.central_cornea]
        x = np.vstack(self.body.comm.allgather(x))
        # |x|² = 2 y y_c + 2 z z_c + (R² − y_c² − z_c²): linear in the centre and R² − |c|²;
        # the centre is free in the symmetry plane (x_c = 0), so a buckle that pushes the
        # cornea sideways (a segmental tire) does not read as a change of curvature
        A = np.column_stack([2.0 * x[:, 1], 2.0 * x[:, 2], np.ones(len(x))])
        (yc, zc, k), *_ = np.linalg.lstsq(A, np.einsum("ij,ij->i", x, x), rcond=None)
        radius = math.sqrt(k + yc**2 + zc**2)
        return {"axial_length_mm": float(apex[2] - pole[2]), "corneal_radius_mm": radius,
                "corneal_power_D": 1000.0 * (KERATOMETRIC_INDEX - 1.0) / radius}

    def lengths(self, optics: dict) -> dict:
        """The optics, and the inflation from the unloaded mesh (not a surgical change:
        kept under its own name; the mesh is the eye at zero pressure)."""
        reference_axial = self.apex.nodes[0][2] - self.pole.nodes[0][2]
        return {"axial_length_mm": optics["axial_length_mm"],
                "corneal_radius_mm": optics["corneal_radius_mm"],
                "corneal_power_D": optics["corneal_power_D"],
                "axial_length_change_from_unloaded_mm": optics["axial_length_mm"] - reference_axial}

    def record_preoperative(self, volume_mm3: float, iop_mmHg: float) -> None:
        """The eye before surgery: every change is measured from it."""
        self.preoperative = self.read() | {"volume_mm3": volume_mm3, "iop_mmHg": iop_mmHg}

    def changes(self, optics: dict, volume_mm3: float, iop_mmHg: float) -> dict:
        """Changes from the eye before surgery: axial length, corneal power, refraction,
        IOP, whole-eye liquid volume. Refraction (spherical equivalent at the cornea):
        ΔSE = −D_AL ΔAL − ΔK, D_AL = 2.7 D per mm of axial length (Gullstrand's schematic
        eye, emmetropic) and ΔK the keratometric power change; negative = myopic shift.
        Absent before the eye before surgery is recorded."""
        pre = self.preoperative
        if not pre:
            return {}
        axial = optics["axial_length_mm"] - pre["axial_length_mm"]
        power = optics["corneal_power_D"] - pre["corneal_power_D"]
        return {"axial_length_change_mm": axial,
                "corneal_power_change_D": power,
                "refraction_change_D": -DIOPTRES_PER_MM * axial - power,
                "iop_change_mmHg": iop_mmHg - pre["iop_mmHg"],
                "volume_change_mm3": volume_mm3 - pre["volume_mm3"]}

    def register(self, checkpoints) -> None:
        checkpoints.value("preoperative", lambda: self.preoperative,
                          lambda saved: setattr(self, "preoperative", dict(saved)))


def rim_margin(rim_gap_mm: float, tolerance: float) -> float:
    """The tear's rim against the closure tolerance (mm): positive = closed by that much,
    negative = open by that much. The rim counts as closed when its widest node-to-surface
    gap (``tear_rim_gap_max_mm``) is below ``tear_closure_tolerance``, as
    ``tear_closed_nts`` has it: closed exactly when the margin is > 0."""
    return tolerance - rim_gap_mm


def rim_verdict(margin_mm: float, error_estimate_mm: float | None = None) -> str | None:
    """``closed`` (margin > 0) or ``open``; with an estimate of the rim gap's
    discretisation error, ``uncertain`` where |margin| <= it (the mesh-converged rim may
    lie on the other side of the tolerance). None without a rim (nan)."""
    if not math.isfinite(margin_mm):
        return None
    if error_estimate_mm is not None and abs(margin_mm) <= error_estimate_mm:
        return "uncertain"
    return "closed" if margin_mm > 0.0 else "open"


class RetinaGaps:
    """The detached retina's gap to the choroid, node by node along the radius to the
    choroid's node it started above (twin nodes of the mesh), and the tear's rim by that
    measure (``tear_closed_radial``). The tear's verdict is the retina contact's
    node-to-surface one (``tear_closed_nts``, ``tear_rim_margin_mm``), which this class
    turns into the margin. Nothing to measure with an attached retina."""

    # gaps within this (mm) of the widest count as tied (a closed rim's nodes all sit at
    # the penalty's penetration, and their order there is round-off, which differs between
    # partitions): of those, the anterior-most node is reported
    RIM_TIE = 1e-4

    def __init__(self, body, tolerance: float):
        self.body, self.tolerance = body, tolerance
        V, eye = body.u.function_space, body.eye
        self.detached = "retina_detached" in eye.names  # false: detachment_height = 0
        self._detached_area: float | None = None
        if not self.detached:
            self.pairing, self.tear_rim = None, np.zeros(0, bool)
            return
        self.pairing = SurfacePairing(V, eye.facets("retina_detached"), eye.facets("choroid_detached"))
        if "tear_edge" not in eye.names:
            self.tear_rim = np.zeros(len(self.pairing.slave_g), bool)
            return
        tear = facet_nodes(V, eye.facets("tear_edge"))
        owned = V.dofmap.index_map.size_local
        tear_global = V.dofmap.index_map.local_to_global(tear[tear < owned].astype(np.int32))
        tear_global = set(np.concatenate(body.comm.allgather(tear_global)).tolist())
        self.tear_rim = np.array([g in tear_global for g in self.pairing.slave_g])

    def rim_nodes(self) -> np.ndarray:
        """Global numbers of the paired retina nodes on the tear's rim."""
        return self.pairing.slave_g[self.tear_rim]

    def widest_rim_node(self, rim: np.ndarray) -> float:
        """Reference polar angle (degrees from the anterior pole) of the tear-rim node with
        the widest gap ``rim`` (ordered as :meth:`rim_nodes`; nan when none is paired).
        The same on every rank: the pairing is gathered."""
        paired = np.isfinite(rim)
        if not paired.any():
            return float("nan")
        x = self.pairing.slave_x[self.tear_rim][paired]
        polar = np.degrees(np.arccos(x[:, 2] / np.linalg.norm(x, axis=1)))
        tied = rim[paired] >= rim[paired].max() - self.RIM_TIE
        return float(polar[tied].min())

    def detached_area(self) -> float:
        """The detached retina's outer face (half eye)."""
        if not self.detached:
            return 0.0
        if self._detached_area is None:
            eye = self.body.eye
            self._detached_area = assemble_scalar(
                dolfinx.fem.Constant(eye.mesh, 1.0) * eye.ds()(eye.tag("retina_detached")),
                self.body.comm)
        return self._detached_area

    def margin(self, measured: dict) -> dict:
        """The rim's margin against the tolerance (:func:`rim_margin`), from the rim gap
        the retina's contact measured (nothing without retina contact)."""
        if "tear_rim_gap_max_mm" not in measured:
            return {}
        return {"tear_rim_margin_mm": rim_margin(measured["tear_rim_gap_max_mm"], self.tolerance)}

    def measure(self) -> dict:
        with self.body.timings("contact_search"):
            gaps = self.pairing.gaps(self.body.u) if self.pairing is not None else np.zeros(1)
        in_contact = gaps < self.tolerance
        return {"retina_choroid_gap_min_mm": float(gaps.min()),
                "retina_choroid_gap_max_mm": float(gaps.max()),
                # nodal estimate: the share of lifted retina nodes back on the choroid
                "retina_contact_area_mm2": 2.0 * self.detached_area() * float(in_contact.mean()),
                "retina_choroid_gap_mean_mm": float(gaps.mean()),
                # every lifted retina node on the tear's rim within the tolerance of the
                # choroid node it started above; not the verdict (tear_closed_nts): a rim
                # slid along the choroid, or carried through it, reads closed here
                "tear_closed_radial": bool(self.tear_rim.any() and self.pairing is not None
                                           and np.all(gaps[self.tear_rim] < self.tolerance))}

