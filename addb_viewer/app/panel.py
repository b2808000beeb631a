"""The review app's controls: playback, flags, proposals, reprocess, diagnosis, display, export.

Only builds the viser GUI elements and keeps their handles; the behaviour is attached
by :class:`~addb_viewer.app.server.ReviewApp`. The controls are shared by every browser
tab (viser's server-wide GUI), so two tabs of one reviewer stay in step.

Keyboard shortcuts go through viser's command palette (:data:`HOTKEYS`). Letters that
viser's camera also uses (W/A/S/D/Q/E, arrow keys) are avoided.
"""

from __future__ import annotations

from dataclasses import dataclass

import viser

from addb_viewer.app.camera import VIEWS
from addb_viewer.app.plots import shading_legend
from addb_viewer.app.state import SPEED_MAX, SPEED_MIN
from addb_viewer.app.timeline import RIGHT_PX, legend_markdown

#: Command label -> (hotkey, description); a hotkey ``"shift+U"`` is U with that modifier.
HOTKEYS: dict[str, tuple[str, str]] = {
    "Play / pause": ("space", "start or stop playback"),
    "Previous frame": ("J", "step one frame back"),
    "Next frame": ("L", "step one frame forward"),
    "Toggle flag": ("F", "toggle unmeasured force on this frame for the selected foot"),
    "Set in point": ("I", "mark the start of a range (past the end of the range: a new one)"),
    "Set out point": ("O", "mark the end of a range (before its start: a new one)"),
    "Next flagged frame": ("N", "jump to the next flagged range"),
    "Next proposal": ("P", "jump to the next pending proposal"),
    "Next frame over Hicks threshold": ("H", "jump to the next range whose residual is too large"),
    "Undo": ("U", "undo your last edit"),
    "Redo": ("shift+U", "redo your last undone edit"),
    "Flag selection": ("G", "flag the timeline's selected frames (selected foot)"),
    "Unflag selection": ("X", "clear the flags of the timeline's selected frames"),
    "Accept selection": ("Y", "accept the pending proposals in the timeline's selection"),
    "Reject selection": ("Z", "reject the pending proposals in the timeline's selection"),
}

#: Widths of the timeline-and-plots panel docked left of the 3D view and of the control
#: panel docked right of it, px: with viser's borders (8 px) they leave a 1280 px wide page
#: (a laptop) a 3D view of 512 px (560 and viser's "large" 384 left 328 px), a 1920 px page
#: 1152 px. A reviewer can drag either panel's inner edge or fold it away (its arrow).
SIDE_WIDTH_PX, MAIN_WIDTH_PX = 440, 320
#: The Foot choice a page starts with (and a newly opened subject).
DEFAULT_FOOT = "both"
#: The Edits line before the shown subject's first edit.
NO_EDITS = "Every edit is saved at once in the review record."
"""The edits' line before an edit (and once a refusal is taken back: "No edits yet" read as
"nothing to undo" after earlier edits)."""
#: The hint of "Apply the named cause and reprocess" where it can be used (elsewhere the
#: hint says why it is disabled: :func:`addb_viewer.app.reprocess.apply_refusal`).
APPLY_HINT = "saves the correction in addb_extensions.json (as addb diagnose --apply) and reprocesses"

LEGEND = (
    "<small>"
    "<span style='color:rgb(30,150,255)'>●</span> observed marker · "
    "<span style='color:rgb(255,140,0)'>●</span> model marker · "
    "<span style='color:rgb(220,20,60)'>—</span> error over threshold<br>"
    "GRF arrows from the CoP: <span style='color:rgb(40,110,255)'>left</span> / "
    "<span style='color:rgb(240,60,60)'>right</span> / "
    "<span style='color:rgb(250,190,0)'>unassigned</span> foot; at the centre of mass: "
    "<span style='color:rgb(0,160,80)'>measured net GRF</span> vs "
    "<span style='color:rgb(190,0,190)'>m(a − g) required</span>; "
    "their mismatch is the residual force.</small>"
)


class EchoedMarkdown:
    """A message shown in two places at once: the edits' line (the Flags folder's, under
    Undo / Redo) is also shown, in small type, under the timeline's buttons, where the keys
    G, X, Y, Z and U act (on a 1280 x 800 window the Flags folder's line is below the fold);
    hidden there while it says :data:`NO_EDITS`, so the charts below keep their place."""

    def __init__(self, main: viser.GuiMarkdownHandle, echo: viser.GuiMarkdownHandle) -> None:
        self.main, self.echo = main, echo
        self.content = main.content

    @property
    def content(self) -> str:
        """The message (markdown)."""
        return self.main.content

    @content.setter
    def content(self, text: str) -> None:
        self.main.content = text
        self.echo.content = f"<small>{text}</small>"
        self.echo.visible = text != NO_EDITS


@dataclass(repr=False)  # viser's handles do not all print
class ReviewPanel:
    """Handles of every control (built by :func:`build_panel`)."""

    status: viser.GuiMarkdownHandle
    error: viser.GuiMarkdownHandle
    recover_record: viser.GuiButtonHandle
    trial: viser.GuiDropdownHandle
    frame: viser.GuiSliderHandle
    transport: viser.GuiButtonGroupHandle
    speed: viser.GuiSliderHandle
    loop: viser.GuiCheckboxHandle
    jump: viser.GuiButtonGroupHandle
    views: viser.GuiButtonGroupHandle
    follow: viser.GuiCheckboxHandle
    foot: viser.GuiDropdownHandle
    toggle_flag: viser.GuiButtonHandle
    marks: viser.GuiButtonGroupHandle
    range_info: viser.GuiMarkdownHandle
    range_flags: viser.GuiButtonGroupHandle
    proposal_info: viser.GuiMarkdownHandle
    proposal_here: viser.GuiButtonGroupHandle
    proposal_all: viser.GuiButtonGroupHandle
    reviewed: viser.GuiCheckboxHandle
    history: viser.GuiButtonGroupHandle
    saved: EchoedMarkdown
    reprocess: viser.GuiButtonHandle
    cancel: viser.GuiButtonHandle
    progress: viser.GuiProgressBarHandle
    job_status: viser.GuiMarkdownHandle
    comparison: viser.GuiMarkdownHandle
    diagnosis: viser.GuiMarkdownHandle
    diagnosis_folder: viser.GuiFolderHandle
    diagnose: viser.GuiButtonHandle
    apply_diagnosis: viser.GuiButtonHandle
    show_labels: viser.GuiCheckboxHandle
    show_markers: viser.GuiCheckboxHandle
    show_bones: viser.GuiCheckboxHandle
    show_forces: viser.GuiCheckboxHandle
    marker_threshold_cm: viser.GuiNumberHandle
    m_per_bw: viser.GuiNumberHandle
    plots_folder: viser.GuiFolderHandle
    side: viser.PanelHandle
    timeline_tab: viser.GuiTabHandle
    timeline: viser.GuiHtmlHandle
    timeline_frame: viser.GuiSliderHandle
    selection: viser.GuiMultiSliderHandle
    selection_info: viser.GuiMarkdownHandle
    selection_edit: viser.GuiButtonGroupHandle
    record_name: viser.GuiTextHandle
    record: viser.GuiButtonHandle
    record_status: viser.GuiMarkdownHandle
    commands: dict[str, viser.CommandHandle]


#: The Selection slider keeps the timeline strip's room on its right: the docked panel's
#: scrollbar floats over the panel's right edge and took the presses on the slider's last
#: frames (a thumb at the last frame could not be grabbed). viser's client gives its range
#: slider the class ``multi-slider`` (the panel has no other) and a width of 100 %.
SLIDER_ROOM = f"<style>div.multi-slider {{ width: calc(100% - {RIGHT_PX}px); }}</style>"


def build_panel(server: viser.ViserServer, *, title: str) -> ReviewPanel:
    """Add the review controls to ``server``'s GUI (see :class:`ReviewPanel`)."""
    gui = server.gui
    gui.configure_theme(titlebar_content=None, control_width="large", dark_mode=False, show_share_button=False)
    gui.main_panel.dock_right()
    gui.main_panel.set_width(MAIN_WIDTH_PX)
    gui.set_panel_label(title)
    h: dict = {}
    h["status"] = gui.add_markdown("Starting…")
    h["error"] = gui.add_markdown("", visible=False)
    # shown only while the review record cannot be opened and its journal can rebuild it
    h["recover_record"] = gui.add_button(
        "Rebuild the review record from its journal", visible=False, color="orange",
        hint="replays annotations.journal (every edit) into a new annotations.json; the damaged file is kept beside it",
    )
    with gui.add_folder("Playback"):
        h["trial"] = gui.add_dropdown("Trial", ("(none)",), initial_value="(none)", disabled=True)
        h["frame"] = gui.add_slider("Frame", min=0, max=1, step=1, initial_value=0, disabled=True)
        h["transport"] = gui.add_button_group("Step", ("◀ Prev", "Play / Pause", "Next ▶"))
        h["speed"] = gui.add_slider("Speed (x)", min=SPEED_MIN, max=SPEED_MAX, step=0.1, initial_value=1.0)
        h["loop"] = gui.add_checkbox("Loop", initial_value=True)
        h["jump"] = gui.add_button_group("Jump to next", ("Flagged", "Proposal", "Over Hicks"))
        h["views"] = gui.add_button_group("View", VIEWS)
        h["follow"] = gui.add_checkbox("Follow pelvis", initial_value=False)
    with gui.add_folder("Flags (unmeasured force)"):
        h["foot"] = gui.add_dropdown("Foot", ("both", "left", "right"), initial_value=DEFAULT_FOOT)
        h["toggle_flag"] = gui.add_button("Toggle flag at this frame", hint="hotkey F")
        h["marks"] = gui.add_button_group("Range", ("Set in", "Set out", "Clear marks"))
        h["range_info"] = gui.add_markdown("Range: no in/out points")
        h["range_flags"] = gui.add_button_group("Range flags", ("Flag range", "Unflag range"))
        h["proposal_info"] = gui.add_markdown("Automatic proposals: none")
        h["proposal_here"] = gui.add_button_group("Proposal here", ("Accept", "Reject"))
        h["proposal_all"] = gui.add_button_group("All proposals", ("Accept all", "Reject all"))
        h["reviewed"] = gui.add_checkbox("Trial reviewed", initial_value=False)
        h["history"] = gui.add_button_group("Edits", ("Undo", "Redo"))
        saved = gui.add_markdown(NO_EDITS)
    with gui.add_folder("Reprocess"):
        h["reprocess"] = gui.add_button("Reprocess", hint="run the solver on this trial with the current flags")
        # its answer right under the button (a warning below a Cancel row went below the fold
        # of a 1366 x 768 window); Cancel only while a run goes on
        h["job_status"] = gui.add_markdown("")
        h["progress"] = gui.add_progress_bar(0.0, animated=True, visible=False)
        h["cancel"] = gui.add_button("Cancel", disabled=True, color="red", visible=False)
        h["comparison"] = gui.add_markdown("")
    h["diagnosis_folder"] = gui.add_folder("Diagnosis", expand_by_default=False)
    with h["diagnosis_folder"]:
        h["diagnose"] = gui.add_button("Diagnose this trial", hint="why its residuals remain: the candidate causes of docs/diagnose, "
                                       "fitted and cross-validated (about 10 s; progress and Cancel above)")
        h["apply_diagnosis"] = gui.add_button("Apply the named cause and reprocess", hint=APPLY_HINT)
        h["diagnosis"] = gui.add_markdown("")
    with gui.add_folder("Display", expand_by_default=False):
        h["show_labels"] = gui.add_checkbox("Marker names", initial_value=False)
        h["show_markers"] = gui.add_checkbox("Markers", initial_value=True)
        h["show_bones"] = gui.add_checkbox("Bones", initial_value=True)
        h["show_forces"] = gui.add_checkbox("Forces", initial_value=True)
        h["marker_threshold_cm"] = gui.add_number("Error line above (cm)", initial_value=2.0, min=0.0, max=100.0, step=0.5)
        h["m_per_bw"] = gui.add_number("Arrow length of 1 BW (m)", initial_value=1.0, min=0.05, max=5.0, step=0.05)
        gui.add_markdown(LEGEND)
    with gui.add_folder("Export", expand_by_default=False):
        h["record_name"] = gui.add_text("File name", initial_value="trial.rrd")
        h["record"] = gui.add_button("Record to Rerun")
        h["record_status"] = gui.add_markdown("")
    # the timeline and the plots: a panel of their own docked left of the 3D view, always
    # visible (the dataset queue adds a tab to it)
    h["side"] = gui.add_panel()
    h["timeline_tab"] = h["side"].add_tab("Timeline and plots")
    with h["timeline_tab"]:
        h["timeline"] = gui.add_html("")
        gui.add_markdown(legend_markdown())
        h["timeline_frame"] = gui.add_slider("Frame", min=0, max=1, step=1, initial_value=0, disabled=True)
        h["selection"] = gui.add_multi_slider("Selection", min=0, max=1, step=1, initial_value=(0, 0), disabled=True)
        gui.add_html(SLIDER_ROOM)
        h["selection_info"] = gui.add_markdown("Drag the ends of Selection to choose frames.")
        h["selection_edit"] = gui.add_button_group("Selected frames", ("Flag", "Unflag", "Accept", "Reject"))
        h["saved"] = EchoedMarkdown(saved, gui.add_markdown(NO_EDITS))
        h["plots_folder"] = gui.add_folder("Plots")
        with h["plots_folder"]:
            gui.add_markdown(shading_legend())
    h["side"].dock_left()
    h["side"].set_width(SIDE_WIDTH_PX)
    h["commands"] = {
        label: gui.add_command(  # type: ignore[arg-type]
            label, description=desc, hotkey=key.rpartition("+")[2], modifier=key.rpartition("+")[0] or None
        )
        for label, (key, desc) in HOTKEYS.items()
    }
    return ReviewPanel(**h)
