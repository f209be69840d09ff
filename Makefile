# Fresh-machine entry points. Everything runs inside a virtualenv in .venv/ that the
# first target creates (Python >= 3.10 with the venv module; no ROS install needed:
# rclpy and the message packages come from PyPI).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
INSTALLED := $(VENV)/.installed
OUT ?= out

.PHONY: demo live-demo test bench clean

$(INSTALLED): setup.py package.xml pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,bench]'
	touch $@

## demo: synthetic drive -> evaluation table + annotated contact sheet in out/demo/
demo: $(INSTALLED)
	rm -rf $(OUT)/demo && mkdir -p $(OUT)/demo
	$(BIN)/speed_sign_synth $(OUT)/demo/drive --truth $(OUT)/demo/truth.csv --seed 7 \
		--duration 24 --lighting mixed
	$(BIN)/speed_sign_eval bag $(OUT)/demo/drive --truth $(OUT)/demo/truth.csv \
		--out $(OUT)/demo/results --contact-sheet $(OUT)/demo/contact_sheet.png
	@echo "results bag: $(OUT)/demo/results   picture: $(OUT)/demo/contact_sheet.png"

## live-demo: node + bag replay + monitor over DDS, all in one command
live-demo: $(INSTALLED)
	$(BIN)/python -m speed_sign_detector.tools.demo --live --out $(OUT)/live-demo

## test: the test suite (what .ci/run runs)
test: $(INSTALLED)
	$(BIN)/python -m pytest -q

## bench: accuracy and speed against the peers, written to out/bench/
bench: $(INSTALLED)
	$(BIN)/python bench/run_all.py --out $(OUT)/bench

clean:
	rm -rf $(VENV) build install log $(OUT) *.egg-info
