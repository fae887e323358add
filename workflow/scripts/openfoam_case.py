"""Rule openfoam_case: render the OpenFOAM case of one patient (vcsflow.render_case)."""
import json
import sys

sys.path.insert(0, snakemake.scriptdir)  # noqa: F821 (snakemake is injected)
import _common  # noqa: E402

log = _common.setup(snakemake, "openfoam_case")  # noqa: F821


def main(smk):
    from vcsflow.openfoam import render_case

    cfd = json.loads(json.dumps(dict(smk.params.cfd)))  # plain dicts/lists
    flavour = cfd.pop("flavour", "auto")
    state = render_case(smk.output.case, smk.input.stl, cfd, flavour=None if flavour == "auto" else flavour)
    log.info("case for %s (flavour %s): background %s cells of %g m, inside point %s, Q %.4g m3/s -> %s",
             smk.wildcards.id, state["flavour"], "x".join(map(str, state["ncells"])),
             state["cfd"]["mesh"]["cell_size"], state["inside_point"], state["flow_rate"], smk.output.case)


_common.run(main, snakemake, log)  # noqa: F821
