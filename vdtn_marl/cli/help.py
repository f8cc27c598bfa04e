"""Help texts of the ``vdtn-marl`` command: the commands, config groups and most used keys,
with defaults read from the shipped configs (``vdtn_marl/conf``)."""

from __future__ import annotations

from importlib import resources
from typing import Any

from vdtn_marl.experiment.compose import CONFIG_PACKAGE

PROG = "vdtn-marl"

COMMANDS = {
    "jocc": "joint optimisation of control and communication (JOCC): the main experiment",
    "train": "train one agent group: task=control (π*), control_impaired (π̃) or rra",
    "eval": "evaluate a run's policies (checkpoint=RUN_DIR), or fixed ones without a checkpoint",
    "bench": "run or resume a leaderboard benchmark (benchmark=NAME); `bench summarize DIR`",
    "envs": "list the registered environments: agents, clocks, descriptions",
    "rollout": "a short random-policy rollout of an environment (quick start)",
}
GROUPS = {
    "scenario": "the simulated world: platoon(s), radio, traces (vdtn_marl/scenarios/)",
    "algo": "the MARL learner",
    "control": "who drives the followers",
    "rra": "who allocates radio resources, and the RRA reward",
    "experiment": "budgets: iterations, batch sizes, evaluation episodes",
}
# Most used keys of each command: (key, what it does). Defaults are read from conf/.
COMMON_KEYS = {
    "jocc": [
        ("rra.kappa1", "weight κ1 of V2I throughput in the RRA reward, in [0, 1]"),
        ("rra.kappa2", "weight κ2 of IVoI; null (default) means 1 − κ1"),
        ("rra.ivoi_estimator", "td or rollout"),
        ("experiment.jocc_iterations", "JOCC iterations"),
        ("seed", "random seed"),
        ("device", "cpu, cuda or cuda:N"),
        ("resume", "true: continue the run in hydra.run.dir"),
    ],
    "train": [
        ("task", "control (π*, perfect observation), control_impaired (π̃) or rra"),
        ("experiment.control_iterations", "PPO iterations when training control"),
        ("experiment.rra_iterations", "PPO iterations when training RRA"),
        ("algo.num_envs", "scenarios collected in parallel"),
        ("algo.lr", "learning rate"),
        ("seed", "random seed"),
        ("device", "cpu, cuda or cuda:N"),
        ("resume", "true: continue the run in hydra.run.dir"),
    ],
    "eval": [
        ("checkpoint", "run directory (its checkpoints/last.pt) or .pt file; null: fixed policies"),
        ("experiment.eval_episodes", "scenarios evaluated"),
        ("experiment.eval_intervals", "control intervals per evaluation episode"),
        ("seed", "random seed (it picks the held-out scenarios)"),
        ("device", "cpu, cuda or cuda:N"),
    ],
}
EXAMPLES = {
    "jocc": [
        "vdtn-marl jocc experiment=smoke",
        "vdtn-marl jocc rra.kappa1=0.7 seed=3",
        "vdtn-marl jocc --cfg job",
        "vdtn-marl -m jocc rra.kappa1=0,0.25,0.5,0.75,1 seed=0,1,2 hydra/launcher=joblib",
        "vdtn-marl bench summarize multirun/jocc/<date_time>",
        "vdtn-marl jocc hydra.run.dir=outputs/jocc/<date_time> resume=true",
    ],
    "train": [
        "vdtn-marl train algo=mappo scenario=platoon4 experiment=smoke",
        "vdtn-marl train task=rra rra=drra algo=ippo",
        "vdtn-marl train task=control_impaired control.augmentation=false",
    ],
    "eval": [
        "vdtn-marl eval checkpoint=outputs/jocc/<date_time>",
        "vdtn-marl eval checkpoint=outputs/jocc/<date_time> experiment.eval_episodes=32",
        "vdtn-marl eval checkpoint=outputs/jocc/<date_time> rra=round_robin",
        "vdtn-marl eval checkpoint=outputs/jocc/<date_time> --cfg job   # the config it uses",
        "vdtn-marl eval control=cacc rra=greedy   # fixed policies, no checkpoint: no EVoI",
        "vdtn-marl -m eval control=cacc rra=greedy,opportunistic seed=0,1,2   # one process",
    ],
}


# Keys of the machine and the invocation rather than of the experiment: eval does not take them
# from the run (and takes the task from the checkpoint itself).
EVAL_FRESH_KEYS = (
    "checkpoint",
    "resume",
    "device",
    "threads",
    "progress",
    "task",
    "warm_start_cache",
)
#: Keys of the run's config that eval does not take either: the run's own loggers (W&B,
#: MLflow: an eval would need their login and log into the run's project); eval's come from
#: its command line (default: csv).
EVAL_OWN_KEYS = ("experiment.loggers",)


# --- help ----------------------------------------------------------------------------------


def _conf_root() -> Any:
    return resources.files(CONFIG_PACKAGE)


def group_options(group: str) -> list[str]:
    """Names of the configs of ``group`` shipped in conf/ (e.g. ``scenario`` -> platoon4, ...)."""
    folder = _conf_root()
    for part in group.split("/"):
        folder = folder / part
    if not folder.is_dir():
        return []
    return sorted(p.name[: -len(".yaml")] for p in folder.iterdir() if p.name.endswith(".yaml"))


def read_conf_yaml(*parts: str) -> dict:
    import yaml

    node = _conf_root()
    for part in parts:
        node = node / part
    try:
        return yaml.safe_load(node.read_text(encoding="utf-8")) or {}
    except (FileNotFoundError, yaml.YAMLError):
        return {}


def _default_choices(config_name: str) -> dict[str, str]:
    choices = {}
    for item in read_conf_yaml(f"{config_name}.yaml").get("defaults", []):
        if isinstance(item, dict):
            choices.update({str(k): str(v) for k, v in item.items()})
    return choices


def _default_value(key: str) -> Any:
    """Default of ``key`` as shipped in conf/ (group defaults, then config.yaml), for help."""
    choices = _default_choices("config")
    group, _, rest = key.partition(".")
    sources = []
    if rest and group in choices:
        sources.append((read_conf_yaml("experiment", f"{choices['experiment']}.yaml"), key))
        sources.append((read_conf_yaml(group, f"{choices[group]}.yaml"), rest))
    else:
        sources.append((read_conf_yaml("config.yaml"), key))
    for data, path in sources:
        node: Any = data
        for part in path.split("."):
            node = node.get(part, KeyError) if isinstance(node, dict) else KeyError
        if node is not KeyError:
            return node
    return "?"


def _fmt_default(value: Any) -> str:
    if value is None:
        return "null"
    return str(value).lower() if isinstance(value, bool) else str(value)


def top_help() -> str:
    lines = [
        f"usage: {PROG} [-m] COMMAND [GROUP=OPTION ...] [KEY=VALUE ...] [HYDRA FLAGS]",
        f"       {PROG} COMMAND --help | {PROG} --version",
        "",
        "Multi-agent RL benchmark: platoon control and C-V2X radio resource allocation in a",
        "Vehicular Digital Twin Network. Configs are Hydra configs (shipped in vdtn_marl/conf).",
        "",
        "commands:",
        *(f"  {name:<9} {text}" for name, text in COMMANDS.items()),
        "",
        "config groups (GROUP=OPTION picks one; * marks the default):",
        *_group_lines("config"),
        "",
        "overrides:",
        "  KEY=VALUE      set any key: rra.kappa1=0.7 seed=3 device=cuda algo.num_envs=32",
        "  -m, --multirun one job per combination: -m jocc rra.kappa1=0,0.5,1 seed=0,1",
        "  hydra/launcher=basic|joblib|submitit_slurm|ray   where the jobs of a sweep run",
        "  hydra.run.dir=DIR / hydra.sweep.dir=DIR          where outputs go",
        "",
        "hydra flags:",
        "  --cfg job      print the composed config and exit (--cfg hydra, --cfg all, --resolve)",
        "  --info         Hydra's view: config search path, defaults tree, plugins",
        "  --hydra-help   Hydra's own help",
        "",
        "examples:",
        "  vdtn-marl envs",
        "  vdtn-marl jocc experiment=smoke",
        "  vdtn-marl train algo=mappo scenario=platoon4 experiment=smoke",
        "  vdtn-marl -m jocc rra.kappa1=0,0.5,1 seed=0,1 hydra/launcher=joblib",
        "  vdtn-marl bench summarize multirun/jocc/<date_time>",
        "",
        f"Run `{PROG} COMMAND --help` for a command's keys and examples. A bad config prints one",
        "line `error: KEY=VALUE ...` and exits with code 2 before anything is written.",
    ]
    return "\n".join(lines)


def _group_lines(config_name: str) -> list[str]:
    defaults = _default_choices(config_name)
    groups = GROUPS if config_name == "config" else {"benchmark": "scenarios × methods × seeds"}
    out = []
    for group, text in groups.items():
        options = [f"{o}*" if o == defaults.get(group) else o for o in group_options(group)]
        out.append(f"  {group:<11} {text}")
        out.append(f"  {'':<11}   {', '.join(options)}")
    return out


def command_help(command: str) -> str:
    if command == "bench":
        return bench_help()
    keys = COMMON_KEYS[command]
    width = max(len(k) for k, _ in keys) + 2
    lines = [
        f"usage: {PROG} [-m] {command} [GROUP=OPTION ...] [KEY=VALUE ...] [HYDRA FLAGS]",
        "",
        f"{COMMANDS[command]}.",
        _COMMAND_DETAILS[command],
        "",
        "config groups (GROUP=OPTION picks one; * marks the default):"
        if command != "eval"
        else "config groups (GROUP=OPTION replaces the run's option; * marks jocc's default):",
        *_group_lines("config"),
        "",
        "most used keys (default):",
        *(
            f"  {k + '=':<{width}} {text} [default: {_help_default(command, k)}]"
            for k, text in keys
        ),
        "  Every key of `--cfg job` can be set; an unknown key or a wrong type is an error.",
        "",
        "sweeps and launchers:",
        f"  {'-m ' + command + ' KEY=A,B,C ...':<33} one job per combination (basic: in turn)",
        "  hydra/launcher=joblib             jobs in parallel processes on this machine",
        "  hydra/launcher=submitit_slurm     jobs on SLURM (pip install 'vdtn-marl[slurm]')",
        "  hydra/launcher=ray                jobs on a Ray cluster (see docs/cli.md)",
        "",
        "outputs: outputs/<command>/<date_time>/ (one run) or multirun/<command>/<date_time>/<n>/",
        *_OUTPUTS[command],
        "",
        "hydra flags: --cfg job | --cfg hydra | --info | --hydra-help",
        "",
        "examples:",
        *(f"  {e}" for e in EXAMPLES[command]),
    ]
    return "\n".join(lines)


# What a run of each command writes in its folder (command help).
_OUTPUTS = {
    "jocc": [
        "  config.yaml (resolved config), metrics.csv, evaluation.csv, checkpoints/last.pt,",
        "  summary.json, plots (*.png), jocc.log (stages, checkpoints, final metrics), .hydra/",
        "  A folder that holds a run is never overwritten: resume=true continues it.",
    ],
    "train": [
        "  config.yaml (resolved config), metrics.csv, evaluation.csv, checkpoints/last.pt,",
        "  summary.json, plots (*.png), train.log (stages, checkpoints, final metrics), .hydra/",
        "  A folder that holds a run is never overwritten: resume=true continues it.",
    ],
    "eval": [
        "  config.yaml (the run's config with your overrides), evaluation.csv, summary.json",
        "  (with `warnings` naming policies the checkpoint never trained; without a checkpoint",
        "  `notes` says there is no EVoI), evaluation_raw.npz (per-scenario arrays), eval.log,",
        "  .hydra/",
        "  video=true: episode.gif (video_format=mp4: episode.mp4) of the first scenario",
    ],
}


def _help_default(command: str, key: str) -> str:
    """A key's default for help: eval takes most keys from the checkpoint's run."""
    if command == "eval" and key.split(".")[0] not in EVAL_FRESH_KEYS and key not in EVAL_OWN_KEYS:
        return "the run's"
    return _fmt_default(_default_value(key))


_COMMAND_DETAILS = {
    "jocc": "Iteration 0 trains control with a random RRA policy; each iteration trains π*\n"
    "(perfect observation) and π̃ (impaired), then the RRA agents with the reward of `rra`,\n"
    "and records per-iteration metrics (docs/model.md §5).",
    "train": "Trains the group named by `task` with `algo` (MAPPO/IPPO) on `scenario`.",
    "eval": "Evaluates the policies of `checkpoint` with the config of its run (scenario, algo,\n"
    "control, rra, experiment, seed); overrides on the command line change it, e.g.\n"
    "experiment.eval_episodes=32, or rra=round_robin to pair the run's control with a baseline.\n"
    "A task=control checkpoint is scored as π* on perfect observations, as its run did.\n"
    "Without `checkpoint`, fixed policies are scored (a control baseline or control=policy,\n"
    "with an RRA baseline or rra=policy): there is no trained π*, so no EVoI and no IVoI.\n"
    "Several policies or seeds in one process: -m with comma-separated values.",
}


def bench_help() -> str:
    lines = [
        f"usage: {PROG} bench [benchmark=NAME] [KEY=VALUE ...] [--cfg job]",
        f"       {PROG} -m bench benchmark=NAME shard=0,1 num_shards=2 hydra/launcher=joblib",
        f"       {PROG} bench summarize SWEEP_DIR [--csv PATH] [--plot PATH]",
        "",
        "bench benchmark=NAME: run a benchmark, scenarios × methods × seeds (conf/benchmark/),",
        "one `jocc` run per cell in OUT_DIR/<scenario>/<method>/seed<k>/, then aggregate it across",
        "seeds (means with 95% Student-t CIs by default, benchmark.interval=t|bca|percentile;",
        "IQM with a bootstrap CI from 10 seeds) into LEADERBOARD.md, leaderboard.json,",
        "leaderboard_marl_eval.json (marl-eval raw data), leaderboard.csv and PNG plots in",
        "REPORT_DIR. Cells with a complete summary.json are skipped: rerun the same command to",
        "resume. `--cfg job` shows the benchmark. video=true adds GIFs (video_format=mp4: MP4s)",
        "of the two trace methods on their best and worst held-out scenario.",
        "",
        "bench summarize: collect every job of a finished sweep (its summary.json, config.yaml",
        "and .hydra/overrides.yaml) into one table, printed and written as SWEEP_DIR/summary.csv,",
        "and plot control cost against V2I throughput per link (Mbps) coloured by κ1, with the",
        "Pareto front, as SWEEP_DIR/pareto_kappa1.png.",
        "",
        "config groups (* marks the default):",
        *_group_lines("bench"),
        "",
        "keys (default):",
        f"  out_dir=DIR        the cells' run directories [default: {_bench_default('out_dir')}]",
        "  report_dir=DIR     where the report goes [default: out_dir]",
        "  shard=K num_shards=N   this job runs cells K, K+N, ... (for -m sweeps) [0, 1]",
        "  cells=[GLOB,...]   run only the cells <scenario>/<method>/seed<k> that match [all]",
        "  run=false          run no cell, only report the complete ones",
        "  report=false       run the cells only",
        "  device=cpu|cuda    device of every run [default: cpu]",
        "",
        "examples:",
        "  vdtn-marl bench benchmark=smoke",
        "  vdtn-marl bench benchmark=reduced report_dir=benchmarks/results",
        "  vdtn-marl bench benchmark=leaderboard --cfg job",
        "  OMP_NUM_THREADS=1 vdtn-marl -m bench benchmark=leaderboard shard=0,1 num_shards=2 \\",
        "      hydra/launcher=joblib",
        "  vdtn-marl bench summarize multirun/jocc/<date_time>",
    ]
    return "\n".join(lines)


def _bench_default(key: str) -> str:
    return str(read_conf_yaml("bench.yaml").get(key, "?"))
