# psurf: two commands. `make demo` and `make test` each create .venv when it is missing.
PY      ?= python3
VENV    := .venv
VPY     := $(VENV)/bin/python
STAMP   := $(VENV)/.installed
export MPLBACKEND := Agg

.PHONY: demo test test-slow bench bench-quick lint venv clean browser

venv: $(STAMP)

# Installs everything the project needs into .venv. VTK's wheels render off-screen through
# EGL or OSMesa when there is no X server; libgl/libegl/osmesa come from Debian when missing.
$(STAMP): pyproject.toml
	@if [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1 && \
	    ! (ldconfig -p 2>/dev/null | grep -q libOSMesa && ldconfig -p | grep -q libEGL_mesa); then \
	    echo ">> installing system GL libraries (apt-get)"; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	        libgl1 libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 libxrender1 >/dev/null) || \
	    echo ">> apt-get failed; off-screen rendering may be unavailable"; \
	fi
	$(PY) -m venv $(VENV)
	$(VPY) -m pip install -q --upgrade pip
	$(VPY) -m pip install -q -e ".[dev]"
	touch $(STAMP)

demo: $(STAMP)
	$(VPY) app.py demo

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
	$(VPY) -m pytest -q -m "not slow"

test-slow: $(STAMP) browser
	$(VPY) -m pytest -q -m slow

# Stage rates per estimator family, 1 vs 2 processes, doubling tables, peak RSS of a 10^6-photon
# 256x192 pass -> out/bench.json (~10 min on 2 cores); bench-quick: a smaller run (~1 min).
bench: $(STAMP)
	$(VPY) benchmarks/run.py

bench-quick: $(STAMP)
	$(VPY) benchmarks/run.py --quick

lint: $(STAMP)
	$(VPY) -m ruff check .

clean:
	rm -rf $(VENV) out .pytest_cache
