# Meshing (blockMesh, snappyHexMesh, checkMesh) and the steady solve (simpleFoam) of one patient.
# A per-patient failure (mesh check failed, divergence, not converged) does NOT fail the job: it
# ends as status.json with converged: false and the reason, which the atlas reads to exclude
# the patient. Broken set-ups (no OpenFOAM installed, unreadable case) fail the job.


rule openfoam_solve:
    conda:
        "../envs/vcs.yaml"
    input:
        setup="results/patients/{id}/case_setup",
    output:
        case=directory("results/patients/{id}/case"),
        status="results/patients/{id}/status.json",
    threads: solve_ranks()
    log:
        "results/logs/openfoam_solve/{id}.log",
    benchmark:
        "results/benchmarks/openfoam_solve/{id}.tsv"
    script:
        "../scripts/openfoam_solve.py"
