# Meshing (blockMesh, snappyHexMesh, checkMesh) and the steady solve (simpleFoam) of one patient.
# A per-patient failure (mesh check failed, divergence, not converged) does NOT fail the job: it
# ends as status.json with converged: false and the reason, which the atlas reads to exclude
# the patient. Broken set-ups (no OpenFOAM installed, unreadable case) fail the job.
# In the report (Patients, one subcategory per patient): the case's residuals.png and, for the runs
# that make them, transient.png / pulsatile.png (a pattern of the case directory: they are not
# outputs of every run), and status.json.


rule openfoam_solve:
    conda:
        "../envs/vcs.yaml"
    input:
        setup="results/patients/{id}/case_setup",
    output:
        case=report(
            directory("results/patients/{id}/case"),
            patterns=["{plot,residuals|transient|pulsatile}.png"],
            caption="../report/patient_solve.rst",
            category="Patients",
            subcategory="{id}",
            labels={"figure": "{plot}"},
        ),
        status=report(
            "results/patients/{id}/status.json",
            caption="../report/patient_status.rst",
            category="Patients",
            subcategory="{id}",
            labels={"figure": "status.json"},
        ),
    threads: solve_ranks()
    log:
        "results/logs/openfoam_solve/{id}.log",
    benchmark:
        "results/benchmarks/openfoam_solve/{id}.tsv"
    script:
        "../scripts/openfoam_solve.py"
