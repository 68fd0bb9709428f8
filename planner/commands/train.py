"""`drograsp train`: train a learned stage on a dataset folder (resumable, seeded)."""

from __future__ import annotations

import argparse

from planner.commands.args import non_negative_int, positive_float, positive_int, share


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "train",
        help="train a learned model (the interaction diffusion model) on a grasp dataset",
        description="Train a learned stage on a dataset made by `drograsp dataset generate`. "
        "Rerunning the same command resumes from the last checkpoint in --out.",
    )
    tsub = p.add_subparsers(dest="train_command", metavar="MODEL", required=True)
    i = tsub.add_parser(
        "interaction",
        help="object cloud + instruction + hand -> wrist pose and anchors (diffusion)",
        description="Train the interaction model (learned.interaction): writes OUT/"
        "interaction.safetensors + .json, OUT/loss.png and checkpoints; --install also copies "
        "the weights into the package (learned/weights/) where `sample` loads them.",
    )
    i.add_argument(
        "--data",
        required=True,
        nargs="+",
        metavar="DIR",
        help="dataset folder(s); several read as one (e.g. data/grasps_v2 my_grasps)",
    )
    i.add_argument("--out", required=True, metavar="DIR", help="run folder (checkpoints, curve)")
    i.add_argument(
        "--minutes",
        type=positive_float,
        default=15.0,
        help="wall-clock budget of the whole run, resumed parts included (default 15)",
    )
    i.add_argument("--steps", type=positive_int, default=None, help="stop after this many steps")
    i.add_argument(
        "--blocks",
        type=positive_int,
        default=None,
        help="only the first N blocks of each dataset folder (the shipped direct weights: 17)",
    )
    i.add_argument("--seed", type=non_negative_int, default=0)
    i.add_argument("--batch", type=positive_int, default=32, help="grasps per step (default 32)")
    i.add_argument("--threads", type=positive_int, default=1, help="torch threads (default 1)")
    i.add_argument("--checkpoint-minutes", type=positive_float, default=3.0, help="default 3")
    i.add_argument(
        "--width", type=positive_int, default=None, help="model width (default: the config's)"
    )
    i.add_argument("--layers", type=positive_int, default=None, help="denoiser layers")
    i.add_argument(
        "--target",
        choices=("anchors", "joints"),
        default="anchors",
        help="what is drawn with the wrist: anchors (the pipeline's first stage, weights "
        "'interaction') or joints (the direct-diffusion ablation, weights 'direct')",
    )
    i.add_argument(
        "--balance",
        type=float,
        default=0.5,
        help="draw grasps with weight count(instruction)^-BALANCE: 0 uniform over grasps, "
        "1 uniform over instructions (default 0.5)",
    )
    i.add_argument(
        "--generic-share",
        type=share,
        default=0.2,
        help="share of steps whose instruction names no category, e.g. 'Use the object by its "
        "handle' (default 0.2; 0 turns it off)",
    )
    i.add_argument(
        "--frame-sign",
        choices=("profile", "moment"),
        default="profile",
        help="how the object's frame tells its ends apart: profile (where the cross-sections "
        "are large; default) or moment (the points' third moment, as the shipped direct "
        "weights were trained)",
    )
    i.add_argument(
        "--turn-share",
        type=share,
        default=0.0,
        help="share of grasps learned with the object's frame turned half round, so the model "
        "reads which end is which from the shape, not the frame's sign (default 0)",
    )
    i.add_argument(
        "--all-rows",
        action="store_true",
        help="learn also from grasps that miss their intent's definition (intent_ok 0)",
    )
    i.add_argument(
        "--intent-flag",
        action="store_true",
        help="with --all-rows: tell the model whether each grasp meets its intent's "
        "definition; sampling asks for grasps that meet it",
    )
    i.add_argument(
        "--relabel",
        action="store_true",
        help="learn each grasp under every intent it meets on its part (run `drograsp dataset "
        "check-intents DIR` first); with --all-rows, grasps meeting none under their own",
    )
    i.add_argument(
        "--anchors-on-part",
        type=non_negative_int,
        default=3,
        metavar="N",
        help="learn only from grasps with at least N of their 4 anchors on the instructed part "
        "(default 3; 0 keeps every grasp)",
    )
    i.add_argument(
        "--unmet-weight",
        type=share,
        default=1.0,
        metavar="W",
        help="with --all-rows: how often, relative to the others, the grasps that miss their "
        "own intent are drawn (0 to 1, default 1)",
    )
    i.add_argument(
        "--install",
        action="store_true",
        help="copy the final weights to learned/weights/ (the shipped model)",
    )
    i.set_defaults(func=run_interaction)
    d = tsub.add_parser(
        "dro",
        help="wrist + anchors + instruction + hand cloud -> hand-object distances (D(R,O))",
        description="Train the D(R,O) network (learned.train_dro): writes OUT/dro.safetensors, "
        "OUT/loss.png and OUT/checkpoint.pt; --install copies the weights to learned/weights/.",
    )
    d.add_argument(
        "--data",
        required=True,
        nargs="+",
        metavar="DIR",
        help="dataset folder(s); several read as one (e.g. data/grasps_v2 my_grasps)",
    )
    d.add_argument("--out", required=True, metavar="DIR", help="run folder (checkpoints, curve)")
    d.add_argument("--minutes", type=positive_float, default=None, help="training time budget")
    d.add_argument("--epochs", type=positive_int, default=None, help="default 20")
    d.add_argument("--steps", type=positive_int, default=None, help="stop after this many steps")
    d.add_argument("--batch", type=positive_int, default=None, help="grasps per step (default 8)")
    d.add_argument("--seed", type=non_negative_int, default=None)
    d.add_argument("--threads", type=positive_int, default=None, help="torch threads (default 1)")
    d.add_argument("--lr", type=positive_float, default=None, help="peak learning rate (1e-3)")
    d.add_argument(
        "--hand-points",
        type=positive_int,
        default=None,
        help="hand points per step whose rows of D enter the losses (default 128)",
    )
    d.add_argument(
        "--pose-weight",
        type=float,
        default=None,
        help="weight of the pose loss through multilateration + Kabsch (default 0.1)",
    )
    d.add_argument(
        "--checkpoint-every",
        type=positive_int,
        default=None,
        help="steps between checkpoints and validations (default 200)",
    )
    d.add_argument(
        "--max-rows",
        type=positive_int,
        default=None,
        help="only the first rows of each split (quick runs)",
    )
    d.add_argument(
        "--blocks",
        type=positive_int,
        default=None,
        help="only the first N blocks of each dataset folder (the shipped network: 17)",
    )
    d.add_argument("--hands", nargs="+", default=None, help="train on these hands' rows only")
    d.add_argument(
        "--no-anchors",
        action="store_true",
        help="the ablation without anchors (farthest point object input, no contact map)",
    )
    d.add_argument("--install", action="store_true", help="copy the weights to learned/weights/")
    d.set_defaults(func=run_dro)


def interaction_setup(args: argparse.Namespace):
    """The model config and training settings the command line asks for."""
    from learned.interaction import InteractionConfig
    from learned.train_interaction import TrainSettings

    config = InteractionConfig(
        target=args.target, intent_flag=args.intent_flag, frame_sign=args.frame_sign
    )
    if args.width is not None:
        config.width = args.width
    if args.layers is not None:
        config.layers = args.layers
    settings = TrainSettings(
        minutes=args.minutes,
        max_steps=args.steps,
        seed=args.seed,
        batch=args.batch,
        threads=args.threads,
        checkpoint_minutes=args.checkpoint_minutes,
        balance=args.balance,
        generic_share=args.generic_share,
        turn_share=args.turn_share,
        all_rows=args.all_rows,
        relabel=args.relabel,
        anchors_on_part=args.anchors_on_part,
        unmet_weight=args.unmet_weight,
        blocks=args.blocks,
    )
    return config, settings


def run_interaction(args: argparse.Namespace) -> int:
    from learned.train_interaction import train

    config, settings = interaction_setup(args)
    data = args.data[0] if len(args.data) == 1 else args.data
    result = train(data, args.out, settings, config, install=args.install)
    val = "n/a" if result.val_loss is None else f"{result.val_loss:.4f}"
    print(
        f"trained {result.steps} steps ({result.resumed_from} before this run) in "
        f"{result.minutes:.1f} min: loss {result.final_loss:.4f}, val loss {val}\n"
        f"weights: {result.weights}\ncurve: {result.curve}"
    )
    return 0


def run_dro(args: argparse.Namespace) -> int:
    from learned.train_dro import run

    return run(args)
