# Vessel Coordinate System (Romero et al. 2024) + OpenFOAM haemodynamic atlas.
#
#   snakemake --profile profiles/local                  # demo: 8 synthetic aortas -> results/atlas/
#   snakemake --profile profiles/local --configfile config/ci.yaml
#   snakemake --report results/report.html             # after a run
#
# Per patient (results/patients/<id>/): vcs_fit -> vcs_wall (or vcs_lumen: cfd geometry surface)
# -> openfoam_case -> openfoam_solve
# -> fields_sample -> patient_qc (qc.png: the QC sheet); then atlas_build over the cohort
# (results/atlas/), atlas_complete (exit status: non-zero with one line when a patient is not in
# the atlas) and results/provenance.json.

from snakemake.utils import min_version

min_version("9.0")

# the repository (this file's folder), also when the workflow is run as workflow/Snakefile (where
# the Snakemake workflow catalog and snakedeploy look for it): workflow.basedir is then workflow/
VCS_REPO = str(workflow.current_basedir)

configfile: "config/config.yaml"
report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/geometry.smk"
include: "workflow/rules/case.smk"
include: "workflow/rules/solve.smk"
include: "workflow/rules/sample.smk"
include: "workflow/rules/qc.smk"
include: "workflow/rules/atlas.smk"
include: "workflow/rules/keep.smk"
include: "workflow/rules/provenance.smk"


rule all:
    input:
        "results/atlas/atlas.json",
        "results/atlas/complete.txt",  # fails the run (after the atlas) when a patient is left out
        patient_files("results/patients/{id}/fields.npz"),
        patient_files("results/patients/{id}/qc.png"),  # per-patient QC sheets (report: Patients)
    default_target: True
