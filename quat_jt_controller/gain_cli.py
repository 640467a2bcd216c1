"""
The gain design's command line: ``design_gains``, ``python -m quat_jt_controller.gain_design``.

Arguments checked (a bad one is one line and status 2), the robot read, :func:`gain_design.design`
run and its files written (``gain_output``). ROS-free.
"""
import argparse
from math import isfinite
from pathlib import Path
import shlex
import sys
from typing import Callable, NoReturn, Optional, Sequence
from xml.etree import ElementTree

from quat_jt_controller import control_law as cl
from quat_jt_controller.gain_design import (
    CRUISE_FRACTION, DEFAULT_FRICTION_EFFORT_SHARE, design, FRICTION_LEARNING)
from quat_jt_controller.gain_output import ENGINES, sim_yaml, to_yaml
from quat_jt_controller.model import ModelError, RobotModel
from quat_jt_runtime.joints import (chain_joints, check_state_rate, default_chain_end,
                                    fixed_end, joint_rows)
from quat_jt_runtime.joints import STATE_RATE_RANGE_HZ
from quat_jt_runtime.payload import Payload


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line (the problem, then where the usage is), status 2."""

    def error(self, message: str) -> NoReturn:
        """Print ``prog: error: message`` on one line and exit with status 2."""
        self.exit(2, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


def _number(low: float, high: float = float('inf'), low_open: bool = True,
            integer: bool = False) -> Callable[[str], float]:
    """Return an argparse type: a finite number in (low, high] (or [low, high])."""
    kind = 'an integer' if integer else 'a finite number'
    interval = f'{"(" if low_open else "["}{low:g}, {high:g}{"]" if isfinite(high) else ")"}'

    def parse(text: str) -> float:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not {kind}') from None
        if not (isfinite(value) and (value > low if low_open else value >= low)
                and value <= high):
            raise argparse.ArgumentTypeError(f'{text} is not {kind} in {interval}')
        return value
    return parse


def _real(text: str) -> float:
    """Return an argparse type's float (NaN and infinities too: a range check follows)."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None


def _check_per_joint(parser: argparse.ArgumentParser, model: RobotModel,
                     args: argparse.Namespace) -> None:
    """Refuse (status 2) a per-joint list of the wrong length, or a posture outside the limits."""
    names = list(model.joint_names)
    for option in ('effort_limits', 'friction', 'preferred_configuration', 'initial_positions',
                   'sim_coulomb', 'sim_viscous'):
        values = getattr(args, option)
        if values is not None and len(values) != model.n:
            parser.error(f'--{option.replace("_", "-")}: {len(values)} '
                         f'value{"" if len(values) == 1 else "s"} for the {model.n} joints '
                         f'{names}')
    limits = list(zip(model.position_lower, model.position_upper))
    for option in ('preferred_configuration', 'initial_positions'):
        values = getattr(args, option)
        outside = [name for name, v, (lo, hi) in zip(names, values or (), limits)
                   if not lo <= v <= hi]
        if outside:
            parser.error(f'--{option.replace("_", "-")}: {values} puts {outside} outside the '
                         f'joint limits {limits}')


def per_joint_values(values: Optional[Sequence[float]], n: int,
                     name: str) -> Optional[list[float]]:
    """Return one value per joint: ``values`` as given, or its one value ``n`` times."""
    if values is None:
        return None
    if len(values) == 1:
        return [float(values[0])] * n
    if len(values) != n:
        raise ValueError(f'{name}: give one value for every joint or {n} (one per joint), got '
                         f'{len(values)}: {list(values)}')
    return [float(v) for v in values]


def _public_argv(argv: Sequence[str]) -> list[str]:
    """Return ``argv`` with the pybullet_data folder written as <pybullet_data>."""
    try:
        import pybullet_data
        folder = pybullet_data.getDataPath()
    except ImportError:  # a controller-only install has no simulator
        folder = None
    return [a.replace(folder, '<pybullet_data>') if folder else a for a in argv]


def _default_chain(parser: argparse.ArgumentParser, args: argparse.Namespace, urdf: str) -> None:
    """Fill in the links and joints not given from the URDF's tree, and say what was chosen."""
    chosen = []
    try:
        if args.base_link is None or args.tip_link is None:
            base, tip, hand = default_chain_end(urdf, args.base_link)
            if args.base_link is None:
                args.base_link = base
                chosen.append(f"--base-link {base} (the URDF's root link)")
            if args.tip_link is None:
                point = (fixed_end(urdf, tip) if cl.Task(args.task) is cl.Task.POSITION
                         else tip)
                args.tip_link = point
                chosen.append(f'--tip-link {point} (the end of its longest chain of revolute '
                              'joints' + (f', the wrist above the hand at {hand}: its fingers '
                                          'are not the arm' if hand else '')
                              + (f', and the fixed links below {tip}: a position task '
                                 'regulates a point, such as a fingertip or a foot'
                                 if point != tip else '') + ')')
        if args.joints is None:
            args.joints = chain_joints(urdf, args.base_link, args.tip_link)
            chosen.append(f'--joints {" ".join(args.joints)} (the movable joints between them)'
                          + _prismatic_note(urdf, args.joints))
    except ValueError as exc:
        parser.error(f'{exc} (--urdf {args.urdf})')
    if chosen:
        print(f'design_gains: {"; ".join(chosen)}', file=sys.stderr)


def _prismatic_note(urdf: str, joints: Sequence[str]) -> str:
    """Name the sliding joints of a default chain (a torso lift), and how to leave them out."""
    rows = {name: (kind, child) for name, kind, _, child in joint_rows(urdf)}
    kinds = [rows[name][0] for name in joints]
    sliding = [name for name, kind in zip(joints, kinds) if kind == 'prismatic']
    if not sliding:
        return ''
    text = (f'; of them {", ".join(sliding)} slide: the goal-configuration ramp '
            '(configuration_ramp) is metres for them, and a slow lift makes a slow arm')
    leading = len(sliding)  # slides under the whole arm (a torso lift): how to leave them out
    if all(kind == 'prismatic' for kind in kinds[:leading]):
        child = rows[sliding[-1]][1]
        text += (f'. To regulate the arm alone (as an arm controller does), give --base-link '
                 f'{child}')
    return text


def _add_design_options(parser: argparse.ArgumentParser) -> None:
    """Add the options of :data:`DESIGN_OPTIONS`: the design's, that no parameter holds."""
    positive, non_negative = _number(0.0), _number(0.0, low_open=False)
    parser.add_argument('--effort-limits', type=positive, nargs='+',
                        help='N m per joint (default: the URDF effort limits)')
    parser.add_argument('--friction-learning', type=non_negative, default=FRICTION_LEARNING,
                        help='how much more than the estimates the regulator may learn at '
                        f'rest, x the estimates (default {FRICTION_LEARNING:g}; 0 = none)')
    parser.add_argument('--friction-effort-share', type=_number(0.0, 0.5, low_open=False),
                        default=DEFAULT_FRICTION_EFFORT_SHARE,
                        help='what the regulator may learn at rest or creeping on a joint '
                        'without a friction estimate, as a share of its effort limit: a '
                        'friction nobody measured (default '
                        f'{DEFAULT_FRICTION_EFFORT_SHARE:g}; 0 turns it off)')
    parser.add_argument('--delays', type=_number(0.0, low_open=False, integer=True), nargs='+',
                        default=[1], help='ticks of delay the sampled loop must be stable with')
    parser.add_argument('--cruise-fraction', type=_number(0.0, 1.0), default=CRUISE_FRACTION,
                        help='the speed far from the goal, as a fraction of the URDF velocity '
                        'limits: a strong joint gets a goal-configuration gain that drives it '
                        f'this fast, within its budget (default {CRUISE_FRACTION:g})')
    parser.add_argument('--approach-time', type=_number(0.0),
                        help='s: shorten the goal-configuration ramp to at most this time at '
                        "the slowest joint's cruising speed, for a faster approach near the "
                        'goal on an arm with slow joints (default: none, the 0.25 rad ramp; '
                        'docs/gain_design.md, section 5)')


# design_gains' options that no controller parameter holds: the file's design_options
# (Design.options), which a design again for the rotor inertia found reads (redesign.py)
DESIGN_OPTIONS = {'effort_limits': 'effort_limits_nm', 'friction_learning': 'friction_learning',
                  'friction_effort_share': 'friction_effort_share', 'delays': 'delays',
                  'cruise_fraction': 'cruise_fraction', 'approach_time': 'approach_time_s'}


class _OptionsParser(_Parser):
    """The design options' parser: a bad one raises ValueError (a parameter, not a shell)."""

    def error(self, message: str) -> NoReturn:
        """Raise ValueError naming the parameter and the problem."""
        raise ValueError(f'design_options: {message}')


def parse_design_options(tokens: Sequence[str], n_joints: int) -> dict:
    """
    Return ``gain_design.design``'s keyword arguments from design_gains ``tokens``.

    ``tokens`` are options of :data:`DESIGN_OPTIONS` as ``design_gains`` takes them (e.g.
    ``['--delays', '1', '2']``); absent ones take design_gains' defaults. Raises ValueError
    naming a bad one, another option, or a list of effort limits not of ``n_joints``.
    """
    parser = _OptionsParser(prog='design_options', add_help=False)
    _add_design_options(parser)
    args = parser.parse_args(list(tokens))
    if args.effort_limits is not None and len(args.effort_limits) != n_joints:
        raise ValueError(f'design_options: --effort-limits: {len(args.effort_limits)} values '
                         f'for {n_joints} joints')
    values = {key: getattr(args, option) for option, key in DESIGN_OPTIONS.items()}
    values['delays'] = tuple(values['delays'])
    return values


def main(argv: Optional[list] = None) -> int:
    """
    ``ros2 run quat_jt_controller design_gains`` / ``python -m ...gain_design``.

    A bad argument (a number, a file, a joint, a link, a list's length) is one line on stderr
    and status 2, as argparse's own; gains that cannot be designed for the robot, or a file
    that cannot be written, one line and status 1.
    """
    from quat_jt_runtime.resources import default_urdf_xml

    non_negative = _number(0.0, low_open=False)
    parser = _Parser(
        prog='design_gains', description='Compute K_p, K_v, Lambda and the '
        'extensions of the regulator from the robot (docs/gain_design.md).')
    parser.add_argument('--urdf', type=Path, help='URDF file (default: the bundled wrist)')
    parser.add_argument('--base-link',
                        help="the frame of the goals (default: the URDF's root link; base_link "
                             'for the wrist)')
    parser.add_argument('--tip-link',
                        help='the link whose pose is regulated (default: the child link of '
                             'the last revolute or continuous joint of the longest chain of '
                             'them; tool0 for the wrist)')
    parser.add_argument('--joints', nargs='+',
                        help='controlled joints (default: the movable joints from the base '
                             'link to the tip link)')
    parser.add_argument('--task', choices=[t.value for t in cl.Task], default='orientation',
                        help="'orientation' (y = e, Eqs. 37/38), 'pose' (y = [p_d - p; e], "
                             "Eqs. 24/32) or 'position' (y = p_d - p: any reachable point, e.g. "
                             'on an arm of 4 or 5 joints)')
    parser.add_argument('--armature', type=_real, nargs='+',
                        help='rotor inertia the drives add about their joints, kg m^2: one '
                        'value for every joint, or one per joint (default 0). Added to the '
                        "diagonal of the URDF's M(q); written to the file as the controller's "
                        'armature')
    parser.add_argument('--payload-mass', type=_real, default=0.0,
                        help='mass the tip link carries that the URDF does not list (a tool, '
                        'a grasped part), kg (default 0); in g(q) and M(q), and written to '
                        "the file as the controller's payload_mass")
    parser.add_argument('--payload-com', type=_real, nargs=3, default=[0.0, 0.0, 0.0],
                        metavar=('X', 'Y', 'Z'),
                        help="where that mass is, m, in the tip link's frame (default 0 0 0)")
    parser.add_argument('--rate', type=_real, default=1000.0,
                        help='the control rate (of joint_states and commands), Hz, in '
                        f'[{STATE_RATE_RANGE_HZ[0]:g}, {STATE_RATE_RANGE_HZ[1]:g}]; the '
                        'sampled loop is checked at it (default 1000)')
    parser.add_argument('--friction', type=non_negative, nargs='+',
                        help='Coulomb friction estimates, N m per joint (default: none)')
    _add_design_options(parser)
    parser.add_argument('--preferred-configuration', type=_number(-float('inf')), nargs='+',
                        help="rad per joint: the posture a redundant arm's goal configuration "
                        'leans to (default: the middle of the ranges)')
    parser.add_argument('--potential', choices=[p.value for p in cl.Potential],
                        default='tanh', help='the potential the file selects')
    parser.add_argument('--robot-note', default='',
                        help='a note on robot_description for the file')
    parser.add_argument('--out', type=Path, help='write here (default: stdout)')
    sim = parser.add_argument_group(
        'simulator config', 'also write a wrist_sim_node parameter file for the same joints')
    sim.add_argument('--sim-out', type=Path, help='write it here')
    sim.add_argument('--initial-positions', type=_number(-float('inf')), nargs='+',
                     help='rad per joint, where the robot starts at rest (default: the middle '
                     'of the ranges)')
    sim.add_argument('--sim-coulomb', type=non_negative, nargs='+',
                     help='the simulated Coulomb friction, N m per joint (default: none)')
    sim.add_argument('--sim-viscous', type=non_negative, nargs='+',
                     help='the simulated viscous friction, N m s/rad per joint (default: none)')
    sim.add_argument('--sim-armature', type=non_negative, nargs='+',
                     help="the simulated rotor inertia, kg m^2 (default: --armature's)")
    sim.add_argument('--sim-engine', choices=ENGINES, default=ENGINES[0],
                     help=f'the physics engine of the simulator (default {ENGINES[0]})')
    args = parser.parse_args(argv)
    try:
        check_state_rate(args.rate, '--rate')
    except ValueError as exc:
        parser.error(str(exc))
    try:
        urdf = args.urdf.read_text() if args.urdf else default_urdf_xml()
    except (OSError, UnicodeDecodeError) as exc:
        parser.error(f'--urdf {args.urdf}: {getattr(exc, "strerror", None) or exc}')
    try:  # before the URDF parser, which prints its own lines for what is not XML
        root = ElementTree.fromstring(urdf).tag
    except ElementTree.ParseError as exc:
        parser.error(f'--urdf {args.urdf}: not XML ({exc})')
    if root != 'robot':
        parser.error(f'--urdf {args.urdf}: not a URDF (its root element is <{root}>, not '
                     '<robot>)')
    if args.urdf is None:  # the bundled wrist
        args.base_link, args.tip_link = args.base_link or 'base_link', args.tip_link or 'tool0'
    else:
        _default_chain(parser, args, urdf)
    try:
        model = RobotModel(urdf, args.base_link, args.tip_link, args.joints)
    except ModelError as exc:
        parser.error(f'{exc} (--urdf {args.urdf or "<the bundled wrist>"})')
    try:  # the flags' words for the payload's checks (a com given is checked, mass or not)
        Payload.create(args.payload_mass, args.payload_com)
    except ValueError as exc:
        parser.error(str(exc).replace('payload_mass', '--payload-mass')
                     .replace('payload_com', '--payload-com'))
    try:  # one value for every joint or one per joint, each finite and >= 0
        if args.armature is not None or args.payload_mass != 0.0:
            model = RobotModel(urdf, args.base_link, args.tip_link, args.joints,
                               None if args.armature is None else
                               per_joint_values(args.armature, model.n, '--armature'),
                               args.payload_mass, args.payload_com)
        sim_armature = per_joint_values(args.sim_armature, model.n, '--sim-armature')
    except (ModelError, ValueError) as exc:
        parser.error(str(exc))
    _check_per_joint(parser, model, args)
    try:
        result = design(model, cl.Task(args.task), args.rate, args.effort_limits,
                        args.friction, tuple(args.delays),
                        friction_learning=args.friction_learning,
                        friction_effort_share=args.friction_effort_share,
                        cruise_fraction=args.cruise_fraction,
                        preferred_configuration_rad=args.preferred_configuration,
                        approach_time_s=args.approach_time)
        command = shlex.join(['python', '-m', 'quat_jt_controller.gain_design']
                             + _public_argv(sys.argv[1:] if argv is None else argv))
        text = to_yaml(result, args.potential, command, args.robot_note)
        sim_text = (sim_yaml(model, args.rate, args.initial_positions, args.sim_coulomb,
                             args.sim_viscous, command, args.robot_note,
                             model.armature if sim_armature is None else sim_armature,
                             args.sim_engine)
                    if args.sim_out else None)  # both checked before either is written
    except ValueError as exc:  # the robot leaves no gains that meet the design's checks
        print(f'design_gains: error: no design: {exc}', file=sys.stderr)
        return 1
    for warning in result.figures['warnings']:
        print(f'design_gains: WARNING: {warning}', file=sys.stderr)
    try:
        if args.out:
            args.out.write_text(text)
            print(f'wrote {args.out}', file=sys.stderr)
        else:
            sys.stdout.write(text)
        if args.sim_out:
            args.sim_out.write_text(sim_text)
            print(f'wrote {args.sim_out}', file=sys.stderr)
    except OSError as exc:
        print(f'design_gains: error: cannot write {exc.filename}: {exc.strerror}',
              file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
