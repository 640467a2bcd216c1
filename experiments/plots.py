"""Plot helpers the experiments share: joint angles and torques against time, limits dashed."""


JOINT_COLORS = ('tab:blue', 'tab:orange', 'tab:green', 'tab:red', 'tab:purple', 'tab:brown')


def plot_torques(ax, t_s, tau_nm, limits_nm, names, title: str) -> None:
    """Each joint's applied torque against time, with its URDF effort limits (+/-) dashed."""
    for j, name in enumerate(names):
        color = JOINT_COLORS[j % len(JOINT_COLORS)]
        ax.plot(t_s, tau_nm[:, j], color=color, lw=1, label=name)
        for sign in (1.0, -1.0):
            ax.axhline(sign * limits_nm[j], color=color, ls='--', lw=0.8)
    ax.set_xlabel('t [s]')
    ax.set_ylabel('applied torque [N m]; limits dashed')
    ax.set_title(title, fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc='upper right', ncol=2)


def plot_angles(ax, t_s, q_rad, lower_rad, upper_rad, names, title: str) -> None:
    """Each joint's angle against time, with its URDF position limits dashed."""
    for j, name in enumerate(names):
        color = JOINT_COLORS[j % len(JOINT_COLORS)]
        ax.plot(t_s, q_rad[:, j], color=color, lw=1, label=name)
        for limit in (lower_rad[j], upper_rad[j]):
            ax.axhline(limit, color=color, ls='--', lw=0.8)
    ax.set_xlabel('t [s]')
    ax.set_ylabel('q [rad]; limits dashed')
    ax.set_title(title, fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc='upper right', ncol=2)
