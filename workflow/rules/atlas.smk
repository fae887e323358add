# Cohort atlas (vcs.atlas): coregistration, shape and flow PCA, shape -> flow regression.
# A patient that failed at any stage (fit, wall, case set-up, mesh, solve, sampling) ends its chain
# with a failure record / status.json / placeholder fields instead of a failed job (see
# workflow/scripts/_failure.py), so the atlas is always built from the others and lists it under
# patients_excluded with the stage and the reason. atlas.npz and the VTP/VTU files of
# vcs.atlas.plots are written beside atlas.json, the PNG figures (once) to results/atlas/figures/
# for `snakemake --report`, with the cohort table (patients.html / .tsv: every patient, its
# status and why it is not in the atlas). Then atlas_complete fails the run, with one line naming
# every patient left out, unless all of them are in the atlas.
#
# In the report (workflow/report/workflow.rst): atlas.json, the explained variance and the table
# under Atlas / Patients; each figure of figures/ under Shape (subcategory: mean shape, mode k) or
# Flow (subcategory: the field), by its file name (atlas_figure_place in common.smk), with the
# caption of its kind (workflow/report/atlas_figure.rst).


rule atlas_build:
    conda:
        "../envs/vcs.yaml"
    input:
        reports=patient_files("results/patients/{id}/fit/fit_report.json"),
        models=patient_files("results/patients/{id}/fit/model.json"),
        fields=patient_files("results/patients/{id}/fields.npz"),
        statuses=patient_files("results/patients/{id}/status.json"),
    output:
        json=report(
            "results/atlas/atlas.json",
            caption="../report/atlas_json.rst",
            category="Atlas",
            subcategory="Cohort",
            labels={"figure": "atlas.json (the numbers)"},
        ),
        npz="results/atlas/atlas.npz",
        figures=report(
            directory("results/atlas/figures"),
            patterns=["{name}.png"],
            caption="../report/atlas_figure.rst",
            category=atlas_figure_category,
            subcategory=atlas_figure_subcategory,
            labels=atlas_figure_labels,
        ),
        patients_html=report(
            "results/atlas/patients.html",
            caption="../report/patients.rst",
            category="Patients",
            subcategory="Cohort",
            labels={"figure": "status of every patient"},
        ),
        patients_tsv="results/atlas/patients.tsv",
    params:
        ids=PATIENT_IDS,
        options=config["atlas"],
    log:
        "results/logs/atlas_build/atlas.log",
    benchmark:
        "results/benchmarks/atlas_build/atlas.tsv"
    script:
        "../scripts/atlas_build.py"


rule atlas_complete:
    # The run's verdict: every patient of the sheet in the atlas (complete.txt), or a failed job
    # whose one line (on the terminal and in the log) names each patient left out, its stage and
    # reason. Runs where Snakemake runs (its line goes to the run's own stderr).
    localrule: True
    conda:
        "../envs/vcs.yaml"
    input:
        json="results/atlas/atlas.json",
    output:
        done="results/atlas/complete.txt",
    params:
        ids=PATIENT_IDS,
    log:
        "results/logs/atlas_complete/atlas.log",
    script:
        "../scripts/atlas_complete.py"
