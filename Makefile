# psurf: two commands. `make demo` and `make test` each create .venv when it is missing.
PY      ?= python3
VENV    := .venv
VPY     := $(VENV)/bin/python
STAMP   := $(VENV)/.installed
export MPLBACKEND := Agg

.PHONY: demo demo-figure showcase-reference test test-slow bench bench-quick bench-mitsuba \
	bench-mitsuba-quick lint venv clean browser

venv: $(STAMP)

# Installs everything the project needs into .venv. VTK's wheels render off-screen through
# EGL or OSMesa when there is no X server; libgl/libegl/osmesa come from Debian when missing,
# and so does Xvfb (xvfb-run), the virtual X server the window's test (make test-slow) opens
# the real window under.
$(STAMP): pyproject.toml
	@if [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1 && \
	    ! (ldconfig -p 2>/dev/null | grep -q libOSMesa && ldconfig -p | grep -q libEGL_mesa \
	       && command -v xvfb-run >/dev/null 2>&1); then \
	    echo ">> installing system GL libraries and Xvfb (apt-get)"; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	        libgl1 libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 libxrender1 \
	        xvfb xauth >/dev/null) || \
	    echo ">> apt-get failed; off-screen rendering (or the Xvfb window test) may be unavailable"; \
	fi
	$(PY) -m venv $(VENV)
	$(VPY) -m pip install -q --upgrade pip
	$(VPY) -m pip install -q -e ".[dev]"
	touch $(STAMP)

# The showcase comparison (scenes/showcase.toml, planes vs fast-multi at equal time): the
# window where a display exists, else out/comparison.png, out/convergence.gif, out/app_*.png.
demo: $(STAMP)
	$(VPY) app.py demo

# The showcase's reference (relMSE in make demo): photon planes, unbiased and here the least
# noisy per second (checked against 45 min of the path tracer: README, "make demo"); ~25 min.
showcase-reference: $(STAMP)
	$(VPY) app.py render scenes/showcase.toml --estimator planes --photons 16000 --time 1500 \
	    --seed 1000 --out scenes/showcase_reference.npz

# The README's first picture: the headless demo's comparison, copied to docs/.
demo-figure: $(STAMP)
	$(VPY) app.py demo --no-window --out out/demo
	cp out/demo/comparison.png docs/demo_comparison.png

# The browser tests (tests/test_web*.py) drive Debian's headless Chromium with selenium; as
# root with apt-get the browser and its driver are installed here, otherwise those tests skip
# saying why.
BROWSER := /usr/bin/chromium
browser:
	@if [ ! -x $(BROWSER) ] || ! command -v chromedriver >/dev/null 2>&1; then \
	    if [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
	        echo ">> installing chromium and chromium-driver (apt-get) for the browser tests"; \
	        (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	            chromium chromium-driver >/dev/null) || \
	        echo ">> apt-get failed; the browser tests will skip"; \
	    else \
	        echo ">> no chromium/chromedriver and no root apt-get: the browser tests will skip"; \
	    fi; \
	fi

test: $(STAMP) browser
	$(VPY) -m pytest -q -m "not slow" -n 2 --dist loadfile --no-loadscope-reorder

test-slow: $(STAMP) browser
	$(VPY) -m pytest -q -m slow

# Stage rates per estimator family, 1 vs 2 processes, doubling tables, peak RSS of a 10^6-photon
# 256x192 pass -> out/bench.json (70 s on the idle 2-core machine, 2026-12-03); bench-quick: smaller.
bench: $(STAMP)
	$(VPY) benchmarks/run.py

bench-quick: $(STAMP)
	$(VPY) benchmarks/run.py --quick

# psurf vs Mitsuba 3's volpath at equal wall time on every bundled scene -> out/vs_mitsuba.json
# and out/vs_mitsuba.md (benchmarks/vs_mitsuba.py; ~1.75 h: 17 reference parts x 300 s, cached in
# out/vs_mitsuba/refs, and 11 cases x 2 x 30 s). Installs the bench extra (Mitsuba from PyPI) and,
# as root, Debian's libllvm19 when no libLLVM >= 17 is there (drjit's LLVM backend aborts on
# LLVM 15/16; without LLVM the scalar variant runs). Never part of make test.
# bench-mitsuba-quick: a few seconds per side, for checking the tool only (not a result).
MITSUBA_STAMP := $(VENV)/.installed-bench
MITSUBA_ARGS ?=

$(MITSUBA_STAMP): $(STAMP)
	@if [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1 && \
	    ! ls /usr/lib/*/libLLVM*.so* 2>/dev/null | grep -Eq 'libLLVM(-|\.so\.)(1[7-9]|[2-9][0-9])'; then \
	    echo ">> installing libllvm19 for Mitsuba's LLVM variant (apt-get)"; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 \
	        >/dev/null) || echo ">> apt-get failed; Mitsuba will use its scalar variant"; \
	fi
	$(VPY) -m pip install -q -e ".[dev,bench]"
	touch $(MITSUBA_STAMP)

bench-mitsuba: $(MITSUBA_STAMP)
	$(VPY) benchmarks/vs_mitsuba.py $(MITSUBA_ARGS)

bench-mitsuba-quick: $(MITSUBA_STAMP)
	$(VPY) benchmarks/vs_mitsuba.py --time 3 --ref-time 20 --photons 200 \
	    --out out/vs_mitsuba_quick.json --md out/vs_mitsuba_quick.md $(MITSUBA_ARGS)

lint: $(STAMP)
	$(VPY) -m ruff check .

clean:
	rm -rf $(VENV) out .pytest_cache
