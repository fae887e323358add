# Cohort atlas (vcs.atlas): coregistration, shape and flow PCA, shape -> flow regression.
# Patients excluded by their status.json are listed in atlas.json with the reason.


rule atlas_build:
    input:
        models=patient_files("results/patients/{id}/fit/model.json"),
        fields=patient_files("results/patients/{id}/fields.npz"),
        statuses=patient_files("results/patients/{id}/status.json"),
    output:
        json="results/atlas/atlas.json",
        npz="results/atlas/atlas.npz",
    params:
        ids=PATIENT_IDS,
        options=config["atlas"],
    log:
        "results/logs/atlas_build/atlas.log",
    benchmark:
        "results/benchmarks/atlas_build/atlas.tsv"
    script:
        "../scripts/atlas_build.py"
