"""``clothlab import SOURCE -o TABLE``: a lab's text/CSV table (column mapping and conventions on the command
line) or any file clothlab reads (``--format merl|utia|astm|...``) -> a clothlab table.

The reading and conversion live in :mod:`clothlab.io.generic` (text) and :mod:`clothlab.io.loader` (the other
formats); this module parses the options and prints what was written.
"""

from __future__ import annotations

from pathlib import Path

from clothlab.cli.options import LazyText, add_force, add_output, names_of, one_of

_TEXT = "text"
_TABLE, _GENERIC, _LOADER = "clothlab.io.table", "clothlab.io.generic", "clothlab.io.loader"


def _choice(parser, flag, module, attribute, what, default, help_text):
    """An option whose choices are ``module.attribute`` (imported only when given or when help is shown)."""
    names = names_of(module, attribute)
    parser.add_argument(flag, default=default, type=one_of(names, what), metavar=what.split()[-1].upper(),
                        help=LazyText(lambda: f"{help_text}: {' | '.join(names())} (default {default})"))


def _degrees(text: str) -> float:
    """An argparse type: a finite angle in plain decimal notation (no ``nan``, ``inf`` or ``1_0``)."""
    import argparse

    from clothlab.errors import ConfigError
    from clothlab.untrusted import parse_number

    try:
        return parse_number(text, error=ConfigError)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(exc.detail) from None


def _conventions(name):
    return lambda: tuple(__import__(_TABLE, fromlist=["CONVENTION_CHOICES"]).CONVENTION_CHOICES[name])


def add_parser(sub):
    p = sub.add_parser(
        "import", help="convert a text/CSV table (or a MERL/UTIA/ASTM/pab-opto/RGL .bsdf file) to a clothlab table",
        description="Read a reflectance table with the column mapping and conventions given here, convert it "
                    "once into clothlab's convention (degrees, phi counter-clockwise from the weft, BRDF in "
                    "1/sr) and write it as a clothlab table (atomically; an existing file only with --force). "
                    "See docs/formats.md, 'Importing a lab's table'.")
    p.add_argument("source", type=Path, help="the file to import")
    add_output(p, "the clothlab table to write (CSV with a YAML header)", metavar="TABLE", required=True)
    formats = names_of(_LOADER, "FORMATS")
    p.add_argument("--format", default=_TEXT, dest="source_format", metavar="FORMAT",
                   type=one_of(formats, "measurement format"),
                   help=LazyText(lambda: f"text (default: the options below) or another format clothlab reads: "
                                         f"{', '.join(f for f in formats() if f != _TEXT)} (their options with "
                                         "--option)"))
    p.add_argument("--columns", metavar="MAP",
                   help="column mapping: positional theta_i,phi_i,theta_o,phi_o,R,G,B ('-' skips a column) or by "
                        "header name theta_i=ti,phi_i=pi,...,R=red (default: the file's header row names them)")
    _choice(p, "--delimiter", _GENERIC, "DELIMITERS", "delimiter", "auto",
            "field separator (auto: semicolon, comma, tab or whitespace, from the first data row)")
    p.add_argument("--comment", default="#", metavar="CHAR",
                   help="comment character: lines (and line ends) after it are skipped (default '#'; '' none)")
    _choice(p, "--header", _GENERIC, "HEADER_CHOICES", "header", "auto",
            "whether the first non-comment line names the columns (auto: when every field starts with a letter)")
    for flag, key, default, text in (
            ("--angle-unit", "angle_unit", "deg", "unit of the four angles"),
            ("--azimuth-zero", "azimuth_zero", "weft", "where the file's phi = 0 points"),
            ("--azimuth-sense", "azimuth_sense", "ccw", "sense of the file's azimuths seen from above the fabric"),
            ("--quantity", "quantity", "brdf", "what the values are: BRDF (1/sr), pi BRDF, or BRDF cos(theta_i)")):
        names = _conventions(key)
        p.add_argument(flag, default=default, type=one_of(names, key.replace("_", " ")), metavar=key.upper(),
                       help=LazyText(lambda n=names, d=default, t=text: f"{t}: {' | '.join(n())} (default {d})"))
    p.add_argument("--azimuth-offset", type=_degrees, default=0.0, metavar="DEG",
                   help="degrees counter-clockwise added to both azimuths after the zero/sense conversion, so "
                        "that phi = 0 lies along the weft (default 0; recorded in the provenance)")
    p.add_argument("--channels", metavar="NAMES", help="names of the value channels in order, e.g. grey or R,G,B")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="an option of the --format reader (e.g. theta_step=5 for merl or bsdf); repeatable")
    add_force(p, "output table")
    p.dash_values = frozenset({"--columns"})  # '-' skips a column: --columns -,theta_o,... is a value
    return p


def _reader_options(items):
    from clothlab.errors import ConfigError
    from clothlab.untrusted import load_yaml_text

    options = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--option expects KEY=VALUE, got {item!r}", field="--option")
        try:
            options[key.strip()] = load_yaml_text(value, error=ConfigError) if value.strip() else ""
        except ConfigError as exc:
            raise ConfigError(f"{key.strip()}: {exc.detail}", field="--option") from None
    return options


def run(args) -> int:
    from clothlab.errors import ConfigError, ResultExistsError

    if args.output.exists() and not args.force:
        raise ResultExistsError("already exists; pass --force to replace it", path=args.output)
    if args.source_format == _TEXT:
        if args.option:
            raise ConfigError("--option is for the readers of --format; the text importer takes the options "
                              "above", field="--option")
        from clothlab.io.generic import import_table

        try:
            path, m = import_table(
                args.source, args.output, overwrite=args.force, columns=args.columns, delimiter=args.delimiter,
                comment=args.comment, header=args.header, angle_unit=args.angle_unit,
                azimuth_zero=args.azimuth_zero, azimuth_sense=args.azimuth_sense,
                azimuth_offset=args.azimuth_offset, quantity=args.quantity, channels=args.channels)
        except ConfigError as exc:  # an option's value: name the option as it is spelt here
            if exc.path is not None or exc.field is None:
                raise
            raise ConfigError(exc.detail, field="--" + exc.field.replace("_", "-")) from None
    else:
        from clothlab.io.loader import load_measurement
        from clothlab.io.table import write_table

        m = load_measurement(args.source, args.source_format, **_reader_options(args.option))
        path = write_table(m, args.output, overwrite=args.force)
    print(f"{path}: {m.n} direction pairs, channels {', '.join(m.channels)}")
    return 0
