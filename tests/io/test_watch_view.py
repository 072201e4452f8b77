"""The live view of zap watch, rendered to text: units, sparklines, link health, rates."""

import re

from rich.console import Console

from zkzap.api.watch import Watcher
from zkzap.codec import zap
from zkzap.io.watch_view import WatchView, value_text
from zkzap.link.zap_bus import open_bus

R = zap.REGISTER_BY_NAME


def render(view):
    console = Console(record=True, width=120, color_system=None)
    console.print(view.render())
    return console.export_text()


def test_values_in_units():
    assert value_text(R["present-voltage"], 121) == "12.1 V"
    assert value_text(R["present-current"], 300) == "300 mA"
    assert value_text(R["feedback-return-mode"], 1) == "1 (Load Data and Echo)"
    assert value_text(R["moving"], None) == "-"


def test_view_shows_each_id_with_health_and_rates():
    bus = open_bus("sim://zap?ids=1,2&faults=2:overload", 57600)
    try:
        bus.store(1, R["goal-position"], 1500)
        w = Watcher(bus, [1, 2, 3], [R["present-position"], R["present-voltage"]], count=5, retries=0)
        list(w.rows())
        text = render(WatchView(w, asked=20))
    finally:
        bus.close()
    assert "5 polls in" in text and "polls/s (20 Hz asked; wire limit" in text
    assert "ID 1" in text and "ID 2" in text and "ID 3" in text
    assert "12 V" in text
    assert "5/5 ok, 0.0% lost" in text and "0/5 ok, 100.0% lost" in text
    assert re.search(r"│ +│ +│ +│ +│ errors overload +│", text)                     # ID 2: a third row
    assert text.count("errors none") == 2                                                  # IDs 1 and 3
    assert "last no-reply STALE" in text                                                   # ID 3 never answered
    spark = [line for line in text.splitlines() if "│ ID 1 " in line][0]
    assert re.search(r"│ [▁▂▃▄▅▆▇█]{5} │", spark)          # five polls of a moving rod
