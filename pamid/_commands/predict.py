"""``pamid predict FIT.json --l0-mm 350``: the force map of a muscle nobody has tested.

FIT.json is what ``pamid compare DATA --pooled --out DIR`` writes (DIR/compare.json, or its
``--json`` output saved): its ``"pooled"`` models (:mod:`pamid._pooled._lomo`). The best one
by leave-one-muscle-out RMSE predicts unless ``--model`` names another. The map is printed
as a table (``--json``: one JSON object) and, with ``--out DIR``, written as prediction.json
and prediction.png (force against contraction per pressure, with the 95 % predictive band).
Exit 0, or 2 for bad input (a file without pooled models, a descriptor the model needs and
was not given, a diameter the fitted muscles did not have).
"""

from __future__ import annotations

import json
from pathlib import Path


def register(subparsers) -> None:
    pred = subparsers.add_parser(
        "predict",
        help="predict the force map of an untested muscle from a pooled fit "
             "(pamid compare --pooled), with 95 %% predictive intervals",
        description="Predict the force of a muscle of the given resting length (and other "
                    "descriptors) from a pooled model of `pamid compare DATA --pooled --out "
                    "DIR` (DIR/compare.json), with the 95 % predictive interval of a new "
                    "muscle: the spread of the tested muscles about the pooled law, measured "
                    "on each muscle left out, and the noise.",
    )
    pred.add_argument("fit", metavar="FIT.json",
                      help="compare.json of `pamid compare DATA --pooled`")
    pred.add_argument("--l0-mm", type=float, required=True, dest="l0_mm",
                      help="resting length of the new muscle in mm")
    pred.add_argument("--diameter-mm", type=float, dest="diameter_mm",
                      help="its diameter in mm (must be one the fitted muscles had where "
                           "they all had one)")
    pred.add_argument("--emax-pct", type=float, dest="emax_pct",
                      help="its maximal contraction at 620 kPa in %% (default, for the Bolen "
                           "law: from the fitted muscles' line in ln l0)")
    pred.add_argument("--pressure-kPa", dest="pressure_kPa", metavar="P1,P2,…",
                      help="pressures of the map in kPa (default 100,200,…,600)")
    pred.add_argument("--contraction-pct", dest="contraction_pct", metavar="K1,K2,…",
                      help="contractions of the map in %% (default 21 points from 0 to "
                           "emax or to the fitted data's largest contraction)")
    pred.add_argument("--model", help="the pooled model to predict with (default: the best "
                                      "by LOMO RMSE that converged)")
    pred.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    pred.add_argument("--out", help="folder for prediction.json and prediction.png")
    pred.set_defaults(func=cmd_predict, outputs=("prediction.json", "prediction.png"))


def _numbers(text: str | None, option: str):
    if text is None:
        return None
    try:
        values = [float(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"{option}: write numbers separated by commas, not {text!r}") from None
    if not values:
        raise ValueError(f"{option}: give at least one number")
    return values


def cmd_predict(args) -> int:
    from .._io import write_text_atomic
    from .._pooled._predict import DEFAULT_PRESSURES_KPA, pick_entry, predict_muscle
    from .._report._pooled import plot_prediction, prediction_table

    path = Path(args.fit)
    try:
        payload = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a JSON file of `pamid compare --pooled` ({exc})") from None
    entry = pick_entry(payload, args.model)
    pressures = _numbers(args.pressure_kPa, "--pressure-kPa") or DEFAULT_PRESSURES_KPA
    descriptors = {"diameter_mm": args.diameter_mm, "emax_pct": args.emax_pct}
    pred = predict_muscle(entry, l0_mm=args.l0_mm, descriptors=descriptors,
                          pressure_kPa=pressures,
                          contraction_pct=_numbers(args.contraction_pct, "--contraction-pct"))
    out = pred.to_dict() | {"source": str(path)}
    if args.out:
        folder = Path(args.out)
        plot_prediction(pred, folder / "prediction.png")
        out["plots"] = ["prediction.png"]
        write_text_atomic(folder / "prediction.json", json.dumps(out, indent=2) + "\n")
    if args.json:
        print(json.dumps(out))
    else:
        print(prediction_table(pred))
    return 0
