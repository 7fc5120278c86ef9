"""The page's layout (trame + Vuetify 3): what sits where, bound to state keys and
triggers by name; no logic (that is :mod:`ui.web.page`).

::

    +----------------------------------------------------------------------------------+
    | psurf   scene [v] [upload]   estimators [A,B     ]   status / compiling...       |
    +----------------------------------------+-----------------------------------------+
    | 1 Trace  2 Create  3 Intersect  ...    |  panels: render | techniques | bounces   |
    | [ 3D view: rotate, zoom ]              |  [render + variance picture: click]     |
    |                                        |  members  [x] a  [ ] b                   |
    | < prev  next >  hit  pass  paths  cam  |  sigma_s  sigma_a  g  photons (sliders) |
    | stage title, caption                   |  Evaluate / Reconstruct table, numbers  |
    +----------------------------------------+-----------------------------------------+
"""

from __future__ import annotations

from trame.ui.vuetify3 import SinglePageLayout
from trame.widgets import client, html
from trame.widgets import vuetify3 as v

from . import _view3d
from .scenes import MAX_UPLOAD

#: Read the chosen file in the browser: refused there when too large (the server checks
#: again), otherwise its text goes to the ``upload`` trigger.
_F = "$event.target.files[0]"
_UPLOAD_JS = (
    f"{_F} && ({_F}.size > {MAX_UPLOAD} ? (upload_error = {_F}.name + ': ' + {_F}.size + "
    f"' bytes, more than the {MAX_UPLOAD // 1024} KiB an uploaded scene may have') : "
    f"{_F}.text().then(t => trigger('upload', [{_F}.name, t])))"
)
#: The window's keys anywhere on the page but in a text box: n / p (next / previous stage),
#: + / - (twice / half as many photon subpaths drawn; the stage text names them).
_KEYS = {"n": "trigger('step', [1])", "p": "trigger('step', [-1])",
         "+": "trigger('paths', [2])", "=": "trigger('paths', [2])",
         "-": "trigger('paths', [0.5])"}
_KEYS_JS = (
    "window.addEventListener('keydown', e => (e.target.tagName == 'INPUT' || busy) ? 0 : ("
    + " : ".join(f"e.key == '{k}' ? {js}" for k, js in _KEYS.items()) + " : 0))"
)
_PICK_JS = ("trigger('pick', [$event.offsetX, $event.offsetY, $event.target.clientWidth, "
            "$event.target.clientHeight])")


def _header(layout) -> None:
    layout.title.set_text("psurf")  # the scene is in its box, the tab's title says both
    with layout.toolbar:
        v.VSpacer()
        v.VSelect(v_model=("scene_name",), items=("scene_items",), label="scene",
                  density="compact", hide_details=True, style="max-width: 230px",
                  disabled=("busy",), classes="mx-1", id="scene-select")
        html.Input(type="file", accept=".toml", change=_UPLOAD_JS, id="upload", __events=["change"],
                   style="max-width: 210px; font-size: 13px", disabled=("busy",))
        v.VCombobox(v_model=("estimators_text",), items=("estimator_items",),
                    label="estimators A,B", density="compact", hide_details=True,
                    style="max-width: 260px", classes="mx-1", disabled=("busy",),
                    id="estimators")
        v.VBtn("apply", click="trigger('set_estimators', [estimators_text])", size="small",
               disabled=("busy",), id="apply-estimators")
        v.VChip("{{ status }}", classes="mx-2", size="small", id="status",
                color=("busy ? 'orange' : 'grey'",))


def _left(view_plotter):
    with v.VCol(cols=6, classes="pa-1"):
        with v.VBtnToggle(v_model=("stage_index",), mandatory=True, density="compact",
                          divided=True, color="primary", id="stages"):
            for i, name in enumerate(("1 Trace", "2 Create", "3 Intersect", "4 Evaluate",
                                      "5 Reconstruct")):
                v.VBtn(name, value=(str(i),), size="small", disabled=("busy",), id=f"stage-{i}")
        with html.Div(style="height: 560px; width: 100%; border: 1px solid #ccc",
                      id="view3d"):
            view = _view3d.remote_view(view_plotter)
        with html.Div(classes="d-flex align-center flex-wrap mt-1"):
            # (label, trigger, id, gap after); narrow padding: one row at 790 px
            for label, js, bid, gap in (
                    ("◀ previous (p)", "trigger('step', [-1])", "prev", "mr-1"),
                    ("next (n) ▶", "trigger('step', [1])", "next", "mr-2"),
                    ("hit −", "trigger('hit', [-1])", "hit-prev", ""),
                    ("hit +", "trigger('hit', [1])", "hit-next", "mr-2"),
                    ("pass −", "trigger('pass', [-1])", "pass-prev", ""),
                    ("pass +", "trigger('pass', [1])", "pass-next", "mr-2"),
                    ("paths −", "trigger('paths', [0.5])", "paths-less", ""),
                    ("paths +", "trigger('paths', [2])", "paths-more", "mr-2")):
                v.VBtn(label, click=js, size="small", disabled=("busy",), id=bid,
                       classes=f"px-2 {gap}")
            v.VBtn("reset camera", click="trigger('reset_camera')", size="small",
                   classes="px-2", id="reset-camera")
        # Under the buttons, so they stay put while the caption's length changes.
        html.Div("{{ title }}", classes="text-subtitle-2 mt-1", id="stage-title")
        html.Div("{{ caption }}", classes="text-body-2", id="caption")
    return view


#: The sliders: state key, label with the value (a JavaScript expression), range, step.
SLIDERS = (
    ("sigma_s", "'σs ' + Number(sigma_s).toFixed(2)", 0.01, 5.0, 0.01),
    ("sigma_a", "'σa ' + Number(sigma_a).toFixed(2)", 0.0, 5.0, 0.01),
    ("g", "'g ' + Number(g).toFixed(2)", -0.9, 0.9, 0.05),
    ("photons_log2", "'photons ' + Math.round(2 ** photons_log2)", 6.64, 15.97, 0.25),
)


def _sliders() -> None:
    with v.VRow(dense=True):
        for key, label, lo, hi, step in SLIDERS:
            with v.VCol(cols=6, classes="py-0", id=f"slider-{key}-row"):
                v.VSlider(v_model=(key,), label=(label,), min=lo, max=hi, step=step,
                          density="compact", hide_details=True, thumb_label=True,
                          disabled=("busy",), id=f"slider-{key}")


def _tables() -> None:
    with html.Div(v_if="stage_index == 3", id="evaluate-table"):
        with v.VTable(density="compact", classes="text-caption"):
            with html.Thead(), html.Tr():
                html.Th("", v_for="c in evaluate_columns", v_text="c")
            with html.Tbody():
                with html.Tr(v_for="r in evaluate.rows"):
                    html.Td("{{ r[k] }}", v_for="k in evaluate_keys")
        html.Div("{{ evaluate.more }}", classes="text-caption")
        html.Div("sum {{ evaluate.total }} {{ evaluate.check ? '= pixel value (check ok)' : "
                 "'!= pixel value (MISMATCH)' }} {{ evaluate.pixel }}", classes="text-caption")
        html.Div("{{ n }}", v_for="n in evaluate.notes", classes="text-caption")
    with html.Div(v_if="stage_index == 4", id="reconstruct-table"):
        html.Div("{{ reconstruct.title }}", classes="text-body-2")
        html.Div("path: {{ reconstruct.path }}", classes="text-caption")
        html.Div("{{ reconstruct.note }}", classes="text-caption")
        with v.VTable(density="compact", classes="text-caption", v_if="reconstruct.rows.length"):
            with html.Thead(), html.Tr():
                html.Th("member"), html.Th("Q = q|n·ψ|"), html.Th("weight")
            with html.Tbody(), html.Tr(v_for="r in reconstruct.rows"):
                html.Td("{{ r.member }}"), html.Td("{{ r.Q }}"), html.Td("{{ r.weight }}")
        html.Div("{{ reconstruct.sum }}", classes="text-caption")
    html.Pre("{{ panel_text }}", v_if="stage_index < 3", id="panel-text",
             style="font-size: 12px; white-space: pre-wrap")


def _right() -> None:
    with v.VCol(cols=6, classes="pa-1"):
        with html.Div(classes="d-flex align-center"):
            with v.VBtnToggle(v_model=("mode",), mandatory=True, density="compact",
                              divided=True, id="modes"):
                for m in ("render", "techniques", "bounces"):
                    v.VBtn(m, value=m, size="small", disabled=("busy",), id=f"mode-{m}")
            v.VBtn("{{ playing ? 'pause' : 'play' }}", click="trigger('play')", size="small",
                   classes="ml-2", id="play")
            v.VSpacer()
            html.A("figure.png", href="download/figure.png", download="psurf-figure.png",
                   classes="mx-2", id="download-png")
            html.A("render.npz", href="download/render.npz", download="psurf-render.npz",
                   id="download-npz")
        html.Img(src=("panels_src",), click=_PICK_JS, id="panels",
                 style="width: 100%; cursor: crosshair; display: block")
        html.Div("pixel ({{ pixel[0] }}, {{ pixel[1] }}): click the render or variance "
                 "panel to pick another", classes="text-caption", id="pixel")
        with html.Div(classes="d-flex flex-wrap align-center my-1", id="members"):
            html.Span("members:", classes="text-caption mr-1", v_if="members.length > 1")
            v.VChip("{{ m.name }}", v_for="(m, i) in members", v_if="members.length > 1",
                    key="m.name", size="small", classes="ma-1",
                    color=("m.on ? 'primary' : 'grey'",), variant=("m.on ? 'flat' : "
                                                                   "'outlined'",),
                    click="trigger('member', [m.name])", disabled=("busy",),
                    id=("'member-' + i",))
        _sliders()
        _tables()


def build(server, view_plotter):
    """The page of one session: header, 3D view and stepper (left), panels, members,
    sliders and tables (right), and the page's message line.

    Returns
    -------
    (SinglePageLayout, PyVistaRemoteView)
        The layout and the 3D view's widget (``update()`` streams a new frame).
    """
    with SinglePageLayout(server, full_height=True) as layout:
        _header(layout)
        with layout.content:
            with v.VContainer(fluid=True, classes="pa-1"):
                v.VAlert("{{ error }}", v_if="error", type="error", density="compact",
                         closable=True, id="error",
                         **{"click:close": "error = ''"})
                v.VAlert("{{ upload_error }}", v_if="upload_error", type="error",
                         density="compact", closable=True, id="upload-error",
                         **{"click:close": "upload_error = ''"})
                client.ClientTriggers(mounted=_KEYS_JS)
                # What tests (and curious students) can read without parsing pictures.
                html.Div("{{ stage }}|{{ pixel[0] }},{{ pixel[1] }}|{{ passes }}|{{ spec }}|"
                         "{{ busy }}|{{ view_token }}", id="probe", style="display: none")
                with v.VRow(dense=True):
                    view = _left(view_plotter)
                    _right()
    return layout, view
