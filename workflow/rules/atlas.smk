# Cohort atlas (vcs.atlas): coregistration, shape and flow PCA, shape -> flow regression.
# Patients excluded by their status.json are listed in atlas.json with the reason.
# atlas.npz and the VTP/VTU files of vcs.atlas.plots are written beside atlas.json; the PNG
# figures are also copied to results/atlas/figures/ for `snakemake --report`.


rule atlas_build:
    conda:
        "../envs/vcs.yaml"
    input:
        models=patient_files("results/patients/{id}/fit/model.json"),
        fields=patient_files("results/patients/{id}/fields.npz"),
        statuses=patient_files("results/patients/{id}/status.json"),
    output:
        json=report("results/atlas/atlas.json", category="Atlas", labels={"file": "atlas.json"}),
        npz="results/atlas/atlas.npz",
        figures=report(
            directory("results/atlas/figures"),
            patterns=["{name}.png"],
            category="Atlas",
            labels={"figure": "{name}"},
        ),
    params:
        ids=PATIENT_IDS,
        options=config["atlas"],
    log:
        "results/logs/atlas_build/atlas.log",
    benchmark:
        "results/benchmarks/atlas_build/atlas.tsv"
    script:
        "../scripts/atlas_build.py"
