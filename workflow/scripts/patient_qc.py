"""Rule patient_qc: the patient's QC sheet (vcs.qc.write_qc_sheet), one PNG, failed patients too."""

import sys
from pathlib import Path

sys.path.insert(0, snakemake.scriptdir)  # noqa: F821 (snakemake is injected)
import _common  # noqa: E402

log = _common.setup(snakemake, "patient_qc")  # noqa: F821


def main(smk):
    from vcs.qc import PatientFiles, write_qc_sheet

    files = PatientFiles(
        smk.wildcards.id,
        mesh=Path(smk.input.mesh),
        fit_dir=Path(smk.input.model).parent,
        case_dir=Path(smk.input.case),
        status=Path(smk.input.status),
        fields_summary=Path(smk.input.fields),
    )
    drawn = write_qc_sheet(files, smk.output.png)
    for name, what in drawn.items():
        log.info("%s: %s", name, what)


_common.run(main, snakemake, log)  # noqa: F821
