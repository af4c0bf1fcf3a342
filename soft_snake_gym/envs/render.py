"""Drawing the robot with matplotlib: headless (Agg canvas) images, or a window.

``BodyRenderer`` owns one figure whose artists are created once and updated per frame: the
body (edges and nodes, head marked, nodes stuck to the ground as orange squares), the recent
trails of the centre of mass and of the head, the centre of mass, the goal direction, a scale
bar over a world grid and the time. The view follows the centre of mass. The Agg canvas is
used directly, so rendering never needs a display and never changes matplotlib's global
backend; ``human=True`` opens a pyplot window instead.
"""

from __future__ import annotations

import numpy as np

__all__ = ["BodyRenderer", "require_interactive_backend"]

_NON_INTERACTIVE = ("agg", "pdf", "ps", "svg", "pgf", "cairo", "template")


def require_interactive_backend() -> None:
    """Raise ``RuntimeError`` unless matplotlib's backend can open a window."""
    import matplotlib

    backend = matplotlib.get_backend().lower()
    if backend in _NON_INTERACTIVE or "inline" in backend:
        raise RuntimeError(
            f"render_mode='human' needs an interactive matplotlib backend, but the backend is "
            f"{backend!r} (no usable display, or MPLBACKEND chose it); set MPLBACKEND to e.g. "
            "TkAgg or QtAgg on a machine with a display, or use render_mode='rgb_array'"
        )


_WATER = "#d8ecf7"
_GROUND = "#efe6d2"


class BodyRenderer:
    """Renders frames of a planar rod.

    Args:
        human: open a pyplot window (needs a display and an interactive backend) instead of
            drawing off-screen.
        ground: colour the background as ground rather than water.
        body_length: rest length of the body [m]; sets the view (2 body lengths wide) and the
            scale bar.
        fps: frames per second of the window in human mode.
        size: image width and height in pixels.
        view_lengths: width of the view in body lengths.
    """

    def __init__(
        self,
        human: bool = False,
        ground: bool = False,
        body_length: float = 1.62,
        fps: int = 100,
        size: tuple[int, int] = (480, 360),
        view_lengths: float = 2.0,
    ) -> None:
        """Build the figure (arguments in the class docstring)."""
        from matplotlib.figure import Figure

        self.human = human
        self.fps = fps
        dpi = 100
        figsize = (size[0] / dpi, size[1] / dpi)
        if human:
            require_interactive_backend()
            import matplotlib.pyplot as plt

            self._plt = plt
            self.fig = plt.figure(figsize=figsize, dpi=dpi)
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg

            self.fig = Figure(figsize=figsize, dpi=dpi)
            FigureCanvasAgg(self.fig)
        self.fig.subplots_adjust(0, 0, 1, 1)
        ax = self.ax = self.fig.add_subplot(1, 1, 1)
        ax.set_facecolor(_GROUND if ground else _WATER)
        ax.set_aspect("equal")
        self.width = view_lengths * body_length
        self.height = self.width * size[1] / size[0]
        bar = self._bar_length = _nice_length(0.25 * self.width)
        from matplotlib.ticker import MultipleLocator

        # a faint world grid (one scale bar apart) shows the motion while the view follows the body
        ax.xaxis.set_major_locator(MultipleLocator(bar))
        ax.yaxis.set_major_locator(MultipleLocator(bar))
        ax.tick_params(length=0, labelbottom=False, labelleft=False)
        ax.grid(True, color="white", lw=0.8, alpha=0.9)
        ax.set_axisbelow(True)
        (self._trail_com,) = ax.plot([], [], color="#7f7f7f", lw=1.0, alpha=0.8)
        (self._trail_head,) = ax.plot([], [], color="#e377c2", lw=1.0, alpha=0.6)
        (self._body,) = ax.plot([], [], color="#1f4e79", lw=4.0, solid_capstyle="round", zorder=3)
        (self._nodes,) = ax.plot([], [], "o", color="#1f4e79", ms=4, zorder=4)
        (self._stuck,) = ax.plot([], [], "s", color="#ff7f0e", ms=6, zorder=5)
        (self._head,) = ax.plot([], [], "o", color="#d62728", ms=7, zorder=5)
        (self._com,) = ax.plot([], [], "+", color="black", ms=12, mew=2, zorder=6)
        (self._path,) = ax.plot([], [], "--", color="#2ca02c", lw=1.5, zorder=2)
        (self._target,) = ax.plot([], [], "*", color="#2ca02c", ms=14, zorder=6)
        self._radius = None
        self._goal = None
        (self._scale,) = ax.plot([], [], color="black", lw=2.5, zorder=6)
        self._scale_text = ax.text(0, 0, f"{bar:g} m", ha="center", va="bottom", fontsize=9, zorder=6)
        self._time_text = ax.text(
            0.02,
            0.97,
            "",
            transform=ax.transAxes,
            ha="left",
            va="top",
            fontsize=10,
            family="monospace",
            zorder=6,
        )
        self._status_text = ax.text(
            0.98,
            0.97,
            "",
            transform=ax.transAxes,
            ha="right",
            va="top",
            fontsize=9,
            color="#d62728",
            zorder=6,
        )

    def draw(
        self,
        x: np.ndarray,
        trail_com: np.ndarray,
        trail_head: np.ndarray,
        time: float,
        goal: np.ndarray,
        title: str = "",
        failure: str | None = None,
        stuck: np.ndarray | None = None,
        target: np.ndarray | None = None,
        target_radius: float = 0.0,
        path: np.ndarray | None = None,
    ) -> np.ndarray | None:
        """Draw one frame.

        Args:
            x: node positions, (N, 2) [m].
            trail_com: recent centre-of-mass positions, (T, 2) [m]; the last row is the current
                centre of mass.
            trail_head: recent head positions, (T, 2) [m].
            time: simulated time [s].
            goal: unit goal direction, (2,).
            title: shown next to the time.
            failure: a failure reason to show, if any.
            stuck: which nodes stick to the ground, (N,) bool, drawn as orange squares.
            target: a target point, (2,) [m], drawn as a green star with a circle of
                ``target_radius`` [m] around it.
            target_radius: the target's success radius [m].
            path: a path to follow, (M, 2) [m], drawn as a dashed green line.

        Returns:
            The image, (height, width, 3) uint8, off-screen; ``None`` in human mode.
        """
        com = trail_com[-1] if len(trail_com) else x.mean(axis=0)
        self._body.set_data(x[:, 0], x[:, 1])
        self._nodes.set_data(x[:, 0], x[:, 1])
        self._head.set_data([x[-1, 0]], [x[-1, 1]])
        held = x[stuck] if stuck is not None else x[:0]
        self._stuck.set_data(held[:, 0], held[:, 1])
        self._com.set_data([com[0]], [com[1]])
        if len(trail_com):
            self._trail_com.set_data(trail_com[:, 0], trail_com[:, 1])
            self._trail_head.set_data(trail_head[:, 0], trail_head[:, 1])
        if path is not None:
            self._path.set_data(path[:, 0], path[:, 1])
        if target is not None:
            from matplotlib.patches import Circle  # matplotlib loads only when drawing

            self._target.set_data([target[0]], [target[1]])
            if self._radius is not None:
                self._radius.remove()
            self._radius = self.ax.add_patch(
                Circle(tuple(target), target_radius, fill=False, color="#2ca02c", lw=1.0, ls=":")
            )
        x0, x1 = com[0] - 0.5 * self.width, com[0] + 0.5 * self.width
        y0, y1 = com[1] - 0.5 * self.height, com[1] + 0.5 * self.height
        self.ax.set_xlim(x0, x1)
        self.ax.set_ylim(y0, y1)
        bx, by = x1 - 0.05 * self.width - self._bar_length, y0 + 0.06 * self.height
        self._scale.set_data([bx, bx + self._bar_length], [by, by])
        self._scale_text.set_position((bx + 0.5 * self._bar_length, by + 0.01 * self.height))
        if self._goal is not None:
            self._goal.remove()
        gx, gy = x0 + 0.08 * self.width, y0 + 0.08 * self.height
        self._goal = self.ax.annotate(
            "goal",
            xy=(gx + 0.1 * self.width * goal[0], gy + 0.1 * self.width * goal[1]),
            xytext=(gx, gy),
            fontsize=8,
            color="#2ca02c",
            va="center",
            ha="center",
            arrowprops={"arrowstyle": "->", "color": "#2ca02c", "lw": 1.5},
        )
        self._time_text.set_text(f"{title}  t = {time:6.2f} s".strip())
        self._status_text.set_text(f"failure: {failure}" if failure else "")
        if self.human:
            self.fig.canvas.draw_idle()
            self._plt.pause(1.0 / self.fps)
            return None
        self.fig.canvas.draw()
        return np.asarray(self.fig.canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        """Release the figure (closes the window in human mode)."""
        if self.human:
            self._plt.close(self.fig)
        self.fig = None


def _nice_length(target: float) -> float:
    """The largest of 1, 2, 5 × 10^k not above ``target``."""
    exp = np.floor(np.log10(target))
    for m in (5.0, 2.0, 1.0):
        if m * 10**exp <= target:
            return float(m * 10**exp)
    return float(10**exp)
