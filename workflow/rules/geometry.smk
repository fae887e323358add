# Geometry: synthetic demo phantoms, the VCS fit (paper Section 2.2) and the Eq. 8 wall STL.
# A patient whose fit or wall fails does not fail the job: the one-line error stays in the log and
# every output holds a failure record instead (workflow/scripts/_failure.py), which the later
# stages pass on and the atlas reads to list the patient as excluded (stage and reason).

# The shell rules call that script as $VCS_FAILURE_SCRIPT (set here, in every Snakemake process, as
# PATH is in common.smk), so that their commands stay the same wherever the repository is.
os.environ.update(
    VCS_FAILURE_SCRIPT=os.path.normpath(os.path.join(workflow.current_basedir, "..", "scripts", "_failure.py"))
)


rule vcs_phantom:
    conda:
        "../envs/vcs.yaml"
    # Synthetic vessel surface (mm, open ends) for the demo cohort; only for sheet rows whose
    # mesh is results/demo/<kind>_seed<N>.stl.
    output:
        stl="results/demo/{kind}_seed{seed}.stl",
        params="results/demo/{kind}_seed{seed}.json",
    params:
        resolution=config["demo"]["resolution"],
    log:
        "results/logs/vcs_phantom/{kind}_seed{seed}.log",
    shell:
        "vcs phantom --kind {wildcards.kind} --seed {wildcards.seed} --resolution {params.resolution}"
        " -o {output.stl:q} --params {output.params:q} > {log:q} 2>&1"


rule vcs_fit:
    conda:
        "../envs/vcs.yaml"
    # Centerline B-spline + RMF frame + wall model rho_w of one patient (L: auto = the knots this
    # vessel needs; the atlas refits every centerline to the cohort's largest L). Bad input (unreadable
    # mesh, ends not found): one line in the log and a failure record in every output.
    input:
        unpack(fit_input),
    output:
        model="results/patients/{id}/fit/model.json",
        report="results/patients/{id}/fit/fit_report.json",
        centerline="results/patients/{id}/fit/centerline.vtp",
        residuals="results/patients/{id}/fit/wall_residuals.vtp",
    params:
        outdir=output_dir,
        units=fit_units,
        ends=fit_ends,
        L=config["vcs"]["L"],
        K=config["vcs"]["K"],
        R=config["vcs"]["R"],
        recentre=config["vcs"]["recentre"],
    log:
        "results/logs/vcs_fit/{id}.log",
    benchmark:
        "results/benchmarks/vcs_fit/{id}.tsv"
    shell:
        "vcs fit {input.mesh:q} -o {params.outdir:q} --units {params.units} {params.ends}"
        " --L {params.L} --K {params.K} --R {params.R} --recentre {params.recentre} > {log:q} 2>&1"
        " || python \"$VCS_FAILURE_SCRIPT\" record fit $? --patient {wildcards.id} --log {log:q} -- {output:q}"


rule vcs_wall:
    conda:
        "../envs/vcs.yaml"
    # The model wall x(tau, theta) (Eq. 8) as a closed multi-solid STL (wall/inlet/outlet) in metres.
    # A failed fit is passed on without running; a failed wall check is recorded like a failed fit.
    input:
        model="results/patients/{id}/fit/model.json",
    output:
        stl="results/patients/{id}/wall/wall.stl",
    params:
        n_tau=wall_n_tau_option(),
        n_theta=config["wall"]["n_theta"],
        extend_inlet=config["wall"]["extend_inlet"],
        extend_outlet=config["wall"]["extend_outlet"],
    log:
        "results/logs/vcs_wall/{id}.log",
    benchmark:
        "results/benchmarks/vcs_wall/{id}.tsv"
    shell:
        "python \"$VCS_FAILURE_SCRIPT\" propagate --patient {wildcards.id} --log {log:q} --upstream {input.model:q}"
        " -- {output:q} || vcs wall {input.model:q} -o {output.stl:q} --units m {params.n_tau} --n-theta {params.n_theta}"
        " --extend-inlet {params.extend_inlet} --extend-outlet {params.extend_outlet} > {log:q} 2>&1"
        " || python \"$VCS_FAILURE_SCRIPT\" record wall $? --patient {wildcards.id} --log {log:q} -- {output:q}"


rule vcs_lumen:
    conda:
        "../envs/vcs.yaml"
    # cfd geometry surface: the patient's own surface closed into a lumen, every end a patch (inlet at
    # the section's tau = 0, outlet at tau = 1, branch_<k> the others), in metres (vcs.lumen). A failed
    # fit is passed on; a surface that cannot be made a lumen is recorded like a failed wall.
    input:
        unpack(lumen_input),
    output:
        stl="results/patients/{id}/lumen/lumen.stl",
        ends="results/patients/{id}/lumen/ends.json",
    params:
        # the model wall's flow extensions (every branch end takes the outlet's), far faces turned to
        # the CFD's background grid (vcs.lumen.build_lumen)
        extend_inlet=config["wall"]["extend_inlet"],
        extend_outlet=config["wall"]["extend_outlet"],
        grid=config.get("cfd", {}).get("mesh", {}).get("background_frame", "axes"),
    log:
        "results/logs/vcs_lumen/{id}.log",
    benchmark:
        "results/benchmarks/vcs_lumen/{id}.tsv"
    shell:
        "python \"$VCS_FAILURE_SCRIPT\" propagate --patient {wildcards.id} --log {log:q} --upstream {input.model:q}"
        " -- {output:q} || vcs lumen {input.mesh:q} --model {input.model:q} -o {output.stl:q} --ends {output.ends:q}"
        " --units m --extend-inlet {params.extend_inlet} --extend-outlet {params.extend_outlet} --grid {params.grid}"
        " > {log:q} 2>&1"
        " || python \"$VCS_FAILURE_SCRIPT\" record lumen $? --patient {wildcards.id} --log {log:q} -- {output:q}"
