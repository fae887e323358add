# OpenFOAM case set-up (vcs.cfd.render_case): dictionaries from templates/openfoam + the wall STL,
# the mesh sized to the vessel (model.json) and the patient's own cell size / inflow (sheet).


rule openfoam_case:
    conda:
        "../envs/vcs.yaml"
    input:
        stl=case_stl,  # the model wall (cfd geometry model) or the patient's lumen (surface)
        model="results/patients/{id}/fit/model.json",  # sizes the mesh (cfd.mesh.cell_size: auto)
        waveform=waveform_input,  # the inflow waveform CSV of a pulsatile run (none: steady)
        outlet_bc=outlet_bc_input,  # the per-outlet RCR table (sheet's outlet_bc) and its cap files (none: none)
    output:
        case=directory("results/patients/{id}/case_setup"),
    params:
        cfd=cfd_params(),
        patient=patient_cfd,
        geometry=cfd_geometry,  # model or surface (the sheet's cfd_geometry, else cfd.geometry)
    log:
        "results/logs/openfoam_case/{id}.log",
    benchmark:
        "results/benchmarks/openfoam_case/{id}.tsv"
    script:
        "../scripts/openfoam_case.py"
