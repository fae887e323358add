# Per-patient QC sheet (vcs.qc): one PNG per patient, in the Snakemake report under Patients.
# Drawn for every patient of the sheet, failed ones too (their sheet says at which stage and why,
# and shows what exists); a panel that cannot be drawn says so in its place, never failing the job.


rule patient_qc:
    conda:
        "../envs/vcs.yaml"
    input:
        mesh=lambda wildcards: PATIENTS[wildcards.id]["mesh"],
        model="results/patients/{id}/fit/model.json",
        report="results/patients/{id}/fit/fit_report.json",
        residuals="results/patients/{id}/fit/wall_residuals.vtp",
        case="results/patients/{id}/case",
        status="results/patients/{id}/status.json",
        fields="results/patients/{id}/fields.json",
    output:
        png=report(
            "results/patients/{id}/qc.png",
            caption="../report/qc.rst",
            category="Patients",
            subcategory="{id}",
            labels={"figure": "QC sheet"},
        ),
    log:
        "results/logs/patient_qc/{id}.log",
    benchmark:
        "results/benchmarks/patient_qc/{id}.tsv"
    script:
        "../scripts/patient_qc.py"
