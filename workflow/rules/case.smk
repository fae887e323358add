# OpenFOAM case set-up (vcs.cfd.render_case): dictionaries from templates/openfoam + the wall STL.


rule openfoam_case:
    conda:
        "../envs/vcs.yaml"
    input:
        stl="results/patients/{id}/wall/wall.stl",
    output:
        case=directory("results/patients/{id}/case_setup"),
    params:
        cfd=cfd_params(),
    log:
        "results/logs/openfoam_case/{id}.log",
    benchmark:
        "results/benchmarks/openfoam_case/{id}.tsv"
    script:
        "../scripts/openfoam_case.py"
