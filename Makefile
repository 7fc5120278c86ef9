# psurf: two commands. `make demo` and `make test` each create .venv when it is missing.
PY      ?= python3
VENV    := .venv
VPY     := $(VENV)/bin/python
STAMP   := $(VENV)/.installed
export MPLBACKEND := Agg

.PHONY: demo demo-figure showcase-reference test test-slow bench bench-quick lint venv clean

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

# The showcase comparison (scenes/showcase.toml, planes vs paper-multi at equal time): the
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

test: $(STAMP)
	$(VPY) -m pytest -q -m "not slow"

test-slow: $(STAMP)
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
