# Resampling of the CFD fields onto the patient's (tau, theta, rho_n) grid (vcs.cfd.resample).


rule fields_sample:
    conda:
        "../envs/vcs.yaml"
    input:
        case="results/patients/{id}/case",
        status="results/patients/{id}/status.json",
        model="results/patients/{id}/fit/model.json",
    output:
        npz="results/patients/{id}/fields.npz",
        summary="results/patients/{id}/fields.json",
        vtu="results/patients/{id}/fields.vtu",
    params:
        grid=config["grid"],
        rho=config["cfd"]["physics"]["rho"],
    log:
        "results/logs/fields_sample/{id}.log",
    benchmark:
        "results/benchmarks/fields_sample/{id}.tsv"
    script:
        "../scripts/fields_sample.py"
