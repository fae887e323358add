"""Rule fields_sample: resample a finished case onto the patient's (tau, theta, rho_n) grid.

Cases without a usable solution (failed at any earlier stage, or not converged: neither SIMPLE nor
a stationary time average of the transient fallback) get placeholder outputs that only carry the
reason and stage: the atlas excludes them from their status anyway. A case that cannot be
resampled gets the same placeholder with stage ``sampling`` (a per-patient failure, not a job
failure), which the atlas reads. A time-averaged case is sampled from its means (U, p, WSS keep
their names; TAWSS and OSI are added); a pulsatile case from its kept cycles' means (TAWSS, OSI,
RRT, ECAP) and its phase instants (vcs.cfd.resample.sample_pulsatile).
"""

import json
import sys
import traceback

sys.path.insert(0, snakemake.scriptdir)  # noqa: F821 (snakemake is injected)
import _common  # noqa: E402

log = _common.setup(snakemake, "fields_sample")  # noqa: F821

EMPTY_VTU = """<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">
  <UnstructuredGrid>
    <Piece NumberOfPoints="0" NumberOfCells="0">
      <Points><DataArray type="Float64" NumberOfComponents="3" format="ascii"></DataArray></Points>
      <Cells>
        <DataArray type="Int64" Name="connectivity" format="ascii"></DataArray>
        <DataArray type="Int64" Name="offsets" format="ascii"></DataArray>
        <DataArray type="UInt8" Name="types" format="ascii"></DataArray>
      </Cells>
    </Piece>
  </UnstructuredGrid>
</VTKFile>
"""


def placeholder(smk, reason: str, stage: str) -> None:
    """Outputs that only carry why this patient has no fields (and at which stage)."""
    import numpy as np

    np.savez_compressed(smk.output.npz, excluded=np.array(reason), stage=np.array(stage))
    with open(smk.output.summary, "w") as fh:
        json.dump({"excluded": reason, "stage": stage}, fh, indent=1)
    with open(smk.output.vtu, "w") as fh:
        fh.write(EMPTY_VTU)


def main(smk):
    from vcs.atlas import status_exclusion
    from vcs.atlas.cohort import status_stage

    with open(smk.input.status) as fh:
        status = json.load(fh)
    # sample every case that has a solution (converged: SIMPLE or a stationary time average; a
    # legacy status with converged_relaxed too, which the atlas includes only with accept_relaxed)
    reason = status_exclusion(status, accept_relaxed=True)
    if reason is not None:
        log.warning("%s excluded, not resampled: %s", smk.wildcards.id, reason)
        placeholder(smk, reason, status_stage(status))
        return

    from vcs.cfd import sample_case, sample_pulsatile, write_fields
    from vcs.vessel import VesselModel

    grid = dict(smk.params.grid)
    kw = {
        "n_tau": grid["n_tau"],
        "n_theta": grid["n_theta"],
        "n_rho": grid["n_rho"],
        "rho_scale": 1e-3,
        "rho_density": float(smk.params.rho),
    }
    try:
        model = VesselModel.load(smk.input.model)
        if status.get("pulsatile"):
            fields = sample_pulsatile(smk.input.case, model, status["pulsatile"], **kw)
        else:
            fields = sample_case(smk.input.case, model, **kw)
        write_fields(fields, smk.output.npz, vtu_path=smk.output.vtu)
    except Exception as exc:  # this patient's case cannot be resampled: recorded, not a cohort stop
        log.error("resampling %s failed\n%s", smk.wildcards.id, traceback.format_exc())
        reason = f"sampling failed: {type(exc).__name__}: {' '.join(str(exc).split())[:400]}"
        placeholder(smk, reason, "sampling")
        return
    log.info(
        "%s resampled on %dx%dx%d -> %s",
        smk.wildcards.id,
        grid["n_tau"],
        grid["n_theta"],
        grid["n_rho"],
        smk.output.npz,
    )


_common.run(main, snakemake, log)  # noqa: F821
