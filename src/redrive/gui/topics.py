"""The Topic Picker (the paper's Figure 6): choose the topics of a log or a ROS 1 master to show.

Left, the *available* topics with their type (and message count and rate for a log); the ones
redrive decodes are bold, the others grey with a tooltip saying why.  Right, the topics to *show*.
**Run** accepts with the shown topics, **Run All Available Topics** with every decodable one; both
emit :attr:`TopicPicker.topics_chosen`.

>>> with open_log("drive.mcap") as log:                             # doctest: +SKIP
...     picker = TopicPicker.for_log(log.topics, duration_s=(log.end_ns - log.start_ns) / 1e9)
>>> picker = TopicPicker.for_master("http://127.0.0.1:11311")       # doctest: +SKIP
>>> if picker.exec() == QtWidgets.QDialog.DialogCode.Accepted:      # doctest: +SKIP
...     topics = picker.chosen_topics()

A master is asked in a worker thread (Qt's global thread pool); an unreachable one shows
"master at URI not reachable" in the status line, and **Refresh** asks again.
"""

from __future__ import annotations

import functools
import logging
import os
import subprocess
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

from PySide6 import QtCore, QtGui, QtWidgets

from redrive.errors import RedriveError
from redrive.io import TopicInfo as LogTopicInfo
from redrive.io.ros.decoders import decoder_for
from redrive.live.ros1 import UNKNOWN_TYPE, list_topics, master_alive
from redrive.live.ros1 import TopicInfo as MasterTopicInfo
from redrive.live.session import ROS_PYTHON

__all__ = [
    "DECODABLE_COLOR",
    "UNDECODABLE_COLOR",
    "PickerTopic",
    "TopicPicker",
    "log_picker_topics",
    "master_picker_topics",
    "ros_status",
    "rospy_problem",
]

logger = logging.getLogger(__name__)

#: Foreground of topics redrive decodes (bold) and of those it does not (grey).
DECODABLE_COLOR = QtGui.QColor(0, 100, 0)
UNDECODABLE_COLOR = QtGui.QColor(140, 140, 140)

_TOPIC_ROLE = QtCore.Qt.ItemDataRole.UserRole


@dataclass(frozen=True, slots=True, kw_only=True)
class PickerTopic:
    """One row of the picker.

    Attributes:
        name: the topic, ``/velodyne_points``.
        msgtype: its type as the source spells it (``sensor_msgs/msg/PointCloud2``).
        detail: what else is worth a glance: ``100 msgs, 10.0 Hz`` or ``1 publisher``.
        why_not: empty when redrive decodes the topic, else why it does not
            (``no decoder for foo_msgs/msg/Bar``).
    """

    name: str
    msgtype: str
    detail: str = ""
    why_not: str = ""

    @property
    def decodable(self) -> bool:
        return not self.why_not

    @property
    def label(self) -> str:
        return "   ".join(p for p in (self.name, self.msgtype, self.detail) if p)


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _summary(rows: Iterable[PickerTopic]) -> str:
    rows = list(rows)
    return f"{_plural(len(rows), 'topic')}, {sum(t.decodable for t in rows)} decodable"


def log_picker_topics(
    log_topics: Mapping[str, LogTopicInfo], *, duration_s: float | None = None
) -> list[PickerTopic]:
    """The rows of a log's topics, by name; the rate is given when ``duration_s`` is."""
    rows = []
    for name in sorted(log_topics):
        info = log_topics[name]
        detail = _plural(info.count, "msg")
        if duration_s is not None and duration_s > 0 and info.count > 1:
            detail += f", {info.count / duration_s:.1f} Hz"
        if info.encoding == "native":
            why_not = ""
        elif not info.has_definition:
            why_not = f"the log has no definition of {info.msgtype}: its messages cannot be read"
        elif decoder_for(info.msgtype) is None:
            why_not = f"no decoder for {info.msgtype}"
        else:
            why_not = ""
        rows.append(PickerTopic(name=name, msgtype=info.msgtype, detail=detail, why_not=why_not))
    return rows


def master_picker_topics(topics: Iterable[MasterTopicInfo]) -> list[PickerTopic]:
    """The rows of a ROS 1 master's topics, by name."""
    rows = []
    for info in sorted(topics, key=lambda t: t.name):
        if info.decodable:
            why_not = ""
        elif info.msg_type == UNKNOWN_TYPE:
            why_not = "nobody publishes it: the master knows no type for it"
        else:
            why_not = f"no decoder for {info.msg_type}"
        detail = _plural(len(info.publishers), "publisher")
        rows.append(
            PickerTopic(name=info.name, msgtype=info.msg_type, detail=detail, why_not=why_not)
        )
    return rows


class _Answer(QtCore.QObject):
    """Carries a master's answer from the worker thread to the GUI thread (a queued signal)."""

    done = QtCore.Signal(int, object)  # generation, list[MasterTopicInfo] | error text


class TopicPicker(QtWidgets.QDialog):
    """The Topic Picker dialog (see the module text).  Build it with :meth:`for_log` or
    :meth:`for_master`; read :meth:`chosen_topics` after it was accepted.

    Signals:
        topics_chosen(list): the chosen topic names, emitted by Run and Run All before accept.
    """

    topics_chosen = QtCore.Signal(list)

    def __init__(
        self,
        topics: Sequence[PickerTopic] = (),
        *,
        source: str = "",
        master_uri: str | None = None,
        timeout_s: float = 2.0,
        parent: QtWidgets.QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.setWindowTitle(f"Topic Picker — {source}" if source else "Topic Picker")
        self.resize(900, 480)
        #: the ROS master asked for topics; None for a log.
        self.master_uri = master_uri
        self._timeout_s = timeout_s
        self._topics: dict[str, PickerTopic] = {}
        self._shown: list[str] = []
        self._chosen: list[str] = []
        self._generation = 0
        # Without a parent: the worker may still hold it when the dialog is gone.
        self._answer = _Answer()
        self._answer.done.connect(self._on_answer)
        self._build()
        self.set_topics(topics)
        if master_uri is None:
            self.refresh_button.hide()

    # -- construction ------------------------------------------------------------------------

    @classmethod
    def for_log(
        cls,
        log_topics: Mapping[str, LogTopicInfo],
        *,
        duration_s: float | None = None,
        source: str = "log",
        parent: QtWidgets.QWidget | None = None,
    ) -> TopicPicker:
        """A picker of a log's topics (``open_log(path).topics``); rates need ``duration_s``."""
        picker = cls(
            log_picker_topics(log_topics, duration_s=duration_s), source=source, parent=parent
        )
        picker.status_label.setText(f"{source}: {_summary(picker._topics.values())}")
        return picker

    @classmethod
    def for_master(
        cls, uri: str, *, timeout_s: float = 2.0, parent: QtWidgets.QWidget | None = None
    ) -> TopicPicker:
        """A picker of the topics of the ROS 1 master at ``uri``, asked in a worker thread."""
        picker = cls(source=uri, master_uri=uri, timeout_s=timeout_s, parent=parent)
        picker.refresh()
        return picker

    def _build(self) -> None:
        self.available_list, available = self._column("Available")
        self.shown_list, shown = self._column("Shown")
        self.available_list.itemDoubleClicked.connect(lambda item: self._move([item], show=True))
        self.shown_list.itemDoubleClicked.connect(lambda item: self._move([item], show=False))

        self.add_button = self._button(
            "Add →", lambda: self._move(self.available_list.selectedItems(), show=True)
        )
        self.remove_button = self._button(
            "← Remove", lambda: self._move(self.shown_list.selectedItems(), show=False)
        )
        self.clear_button = self._button("Clear Topics", self.clear_topics)
        self.refresh_button = self._button("Refresh", self.refresh)
        self.run_button = self._button("Run", self.run)
        self.run_all_button = self._button("Run All Available Topics", self.run_all)
        self.cancel_button = self._button("Cancel", self.reject)
        self.run_button.setDefault(True)
        self.run_all_button.setToolTip("Run with every topic redrive decodes")

        middle = QtWidgets.QVBoxLayout()
        middle.addStretch(1)
        for button in (self.add_button, self.remove_button, self.clear_button):
            middle.addWidget(button)
        middle.addStretch(1)

        lists = QtWidgets.QHBoxLayout()
        lists.addLayout(available, 3)
        lists.addLayout(middle)
        lists.addLayout(shown, 2)

        self.status_label = QtWidgets.QLabel()
        self.status_label.setWordWrap(True)
        self.status_label.setTextInteractionFlags(
            QtCore.Qt.TextInteractionFlag.TextSelectableByMouse
        )
        bottom = QtWidgets.QHBoxLayout()
        bottom.addWidget(self.status_label, 1)
        for button in (self.refresh_button, self.run_all_button, self.run_button):
            bottom.addWidget(button)
        bottom.addWidget(self.cancel_button)

        layout = QtWidgets.QVBoxLayout(self)
        layout.addLayout(lists, 1)
        layout.addLayout(bottom)

    @staticmethod
    def _button(text: str, slot: Callable[[], object]) -> QtWidgets.QPushButton:
        button = QtWidgets.QPushButton(text)
        button.clicked.connect(slot)
        return button

    @staticmethod
    def _column(title: str) -> tuple[QtWidgets.QListWidget, QtWidgets.QVBoxLayout]:
        """A multi-selection list under a bold title."""
        widget = QtWidgets.QListWidget()
        widget.setObjectName(f"{title.lower()} topics")
        widget.setSelectionMode(QtWidgets.QAbstractItemView.SelectionMode.ExtendedSelection)
        box = QtWidgets.QVBoxLayout()
        box.addWidget(QtWidgets.QLabel(f"<b>{title}</b>"))
        box.addWidget(widget, 1)
        return widget, box

    # -- state -------------------------------------------------------------------------------

    def set_topics(self, topics: Sequence[PickerTopic]) -> None:
        """Replace the available topics; shown topics still available stay shown."""
        self._topics = {t.name: t for t in topics}
        self._shown = [name for name in self._shown if name in self._topics]
        self._render()

    def available_topics(self) -> list[str]:
        """The topics in the left list, in its order."""
        return [name for name in self._topics if name not in self._shown]

    def shown_topics(self) -> list[str]:
        """The topics in the right list, in the order they were added."""
        return list(self._shown)

    def decodable_topics(self) -> list[str]:
        """Every topic redrive decodes, shown or not."""
        return [name for name, t in self._topics.items() if t.decodable]

    def chosen_topics(self) -> list[str]:
        """The topics Run or Run All chose (empty before either)."""
        return list(self._chosen)

    def item(self, topic: str) -> QtWidgets.QListWidgetItem | None:
        """The list item of ``topic`` (in whichever list holds it)."""
        for widget in (self.available_list, self.shown_list):
            for row in range(widget.count()):
                item = widget.item(row)
                if item.data(_TOPIC_ROLE) == topic:
                    return item
        return None

    def _make_item(self, topic: PickerTopic) -> QtWidgets.QListWidgetItem:
        item = QtWidgets.QListWidgetItem(topic.label)
        item.setData(_TOPIC_ROLE, topic.name)
        font = item.font()
        font.setBold(topic.decodable)
        item.setFont(font)
        item.setForeground(QtGui.QBrush(DECODABLE_COLOR if topic.decodable else UNDECODABLE_COLOR))
        why = topic.why_not or f"{topic.msgtype} — redrive decodes it"
        item.setToolTip(f"{topic.name}: {why}")
        return item

    def _render(self) -> None:
        for widget, names in (
            (self.available_list, self.available_topics()),
            (self.shown_list, self._shown),
        ):
            widget.clear()
            for name in names:
                widget.addItem(self._make_item(self._topics[name]))
        self._update_buttons()

    def _update_buttons(self) -> None:
        self.run_button.setEnabled(bool(self._shown))
        self.run_all_button.setEnabled(any(t.decodable for t in self._topics.values()))
        self.clear_button.setEnabled(bool(self._shown))

    def _move(self, items: Iterable[QtWidgets.QListWidgetItem], *, show: bool) -> None:
        names = [str(item.data(_TOPIC_ROLE)) for item in items]
        if show:
            self._shown += [n for n in names if n not in self._shown]
        else:
            self._shown = [n for n in self._shown if n not in names]
        self._render()

    def show_topics(self, topics: Iterable[str]) -> None:
        """Move ``topics`` (those the source has) to the shown list, as Add does."""
        self._shown += [t for t in topics if t in self._topics and t not in self._shown]
        self._render()

    def clear_topics(self) -> None:
        """Move every shown topic back to the available list (Clear Topics)."""
        self._shown = []
        self._render()

    def run(self) -> None:
        """Accept with the shown topics (Run)."""
        self._finish(self.shown_topics())

    def run_all(self) -> None:
        """Accept with every decodable topic (Run All Available Topics)."""
        self._finish(self.decodable_topics())

    def _finish(self, topics: list[str]) -> None:
        self._chosen = list(topics)
        self.topics_chosen.emit(list(topics))
        self.accept()

    # -- the live master -----------------------------------------------------------------------

    def refresh(self) -> None:
        """Ask the master for its topics again, in a worker thread (no-op for a log)."""
        uri = self.master_uri
        if uri is None:
            return
        self._generation += 1
        generation, timeout_s, answer = self._generation, self._timeout_s, self._answer
        self.status_label.setText(f"asking the ROS master at {uri} for its topics …")
        self.refresh_button.setEnabled(False)

        def query() -> None:
            result: list[MasterTopicInfo] | str
            try:
                result = list_topics(uri, timeout_s=timeout_s)
            except RedriveError as err:
                result = str(err)
            answer.done.emit(generation, result)  # queued to the GUI thread

        QtCore.QThreadPool.globalInstance().start(query)

    @QtCore.Slot(int, object)
    def _on_answer(self, generation: int, result: object) -> None:
        if generation != self._generation:
            return  # an older refresh
        self.refresh_button.setEnabled(True)
        if isinstance(result, str):
            self.status_label.setText(f"master at {self.master_uri} not reachable")
            self.status_label.setToolTip(result)
            logger.info("%s", result)
            return
        assert isinstance(result, list)
        rows = master_picker_topics(result)
        self.set_topics(rows)
        self.status_label.setToolTip("")
        self.status_label.setText(f"master at {self.master_uri}: {_summary(rows)}")


@functools.cache
def rospy_problem() -> str | None:
    """Why the ROS 1 scraper cannot run here (no ``/usr/bin/python3``, rospy does not import under
    it), or None when it can.  Runs the interpreter once per process (cached)."""
    if not ROS_PYTHON.is_file():
        return f"{ROS_PYTHON} is missing: the ROS 1 scraper runs under Debian's python3 with rospy"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    try:
        probe = subprocess.run(
            [str(ROS_PYTHON), "-c", "import rospy"],
            capture_output=True,
            text=True,
            env=env,
            timeout=30,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired) as err:
        return f"cannot run {ROS_PYTHON} to look for rospy ({err})"
    if probe.returncode != 0:
        last = (probe.stderr.strip().splitlines() or ["no output"])[-1]
        return f"rospy does not import under {ROS_PYTHON} ({last}); install python3-rospy"
    return None


def ros_status(uri: str, *, timeout_s: float = 1.0) -> str:
    """Two lines for the log box: whether the ROS master at ``uri`` answers, and whether rospy is
    there for the scraper.  Blocks up to ``timeout_s`` plus the first rospy probe: call it from a
    worker thread."""
    try:
        alive = master_alive(uri, timeout_s=timeout_s)
    except RedriveError as err:
        master = f"ROS master: {err}"
    else:
        master = f"ROS master at {uri}: {'reachable' if alive else 'not reachable'}"
    problem = rospy_problem()
    scraper = f"rospy: {problem}" if problem else f"rospy: available under {ROS_PYTHON}"
    return f"{master}\n{scraper}"
