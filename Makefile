# Fresh-machine entry points. Everything runs inside a virtualenv in .venv/ that the
# first target creates (Python >= 3.11 with the venv module; no ROS install needed:
# rclpy and the message packages come from PyPI).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
INSTALLED := $(VENV)/.installed
OUT ?= out

.PHONY: demo live-demo test bench bank clean

$(INSTALLED): setup.py package.xml pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,bench]'
	touch $@

## demo: synthetic drive -> evaluation table + annotated contact sheet in out/demo/
demo: $(INSTALLED)
	rm -rf $(OUT)/demo && mkdir -p $(OUT)/demo
	$(BIN)/speed_sign_synth $(OUT)/demo/drive --truth $(OUT)/demo/truth.csv --seed 7 \
		--duration 24 --lighting mixed --compressed
	$(BIN)/speed_sign_eval bag $(OUT)/demo/drive --truth $(OUT)/demo/truth.csv \
		--out $(OUT)/demo/results --with-images --contact-sheet $(OUT)/demo/contact_sheet.png
	@echo "results bag (opens in Foxglove): $(OUT)/demo/results   picture: $(OUT)/demo/contact_sheet.png"

## live-demo: node + bag replay + monitor over DDS (real rclpy, Fast DDS), in one command;
## the monitor prints a line per diagnostics report and, when the drive has ended, the
## final state (the node idle, its counts, the limit it holds)
live-demo: $(INSTALLED)
	rm -rf $(OUT)/live-demo && mkdir -p $(OUT)/live-demo
	$(BIN)/speed_sign_synth $(OUT)/live-demo/drive --seed 3 --duration 15 --compressed
	@set -e; export FASTRTPS_DEFAULT_PROFILES_FILE=$(CURDIR)/config/fastdds_large_images.xml; \
	$(BIN)/speed_sign_detector --ros-args -r image/compressed:=/camera/image_raw/compressed & \
	node=$$!; trap 'kill -TERM $$node 2>/dev/null || true; wait $$node || true' EXIT; \
	$(BIN)/speed_sign_monitor --timeout 120 & monitor=$$!; \
	$(BIN)/speed_sign_replay $(OUT)/live-demo/drive --restamp --wait 120 -q; \
	sleep 2; kill -TERM $$monitor; wait $$monitor || true

## test: the test suite (what .ci/run runs)
test: $(INSTALLED)
	$(BIN)/python -m pytest -q

## bank: rebuild the shipped filter bank from ../shared/data (reproducible: fixed seed, and one
## BLAS thread, so that the core count does not change the rounding of the networks' training)
DATA ?= ../shared/data
ONE_BLAS_THREAD = OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
bank: $(INSTALLED)
	$(ONE_BLAS_THREAD) $(BIN)/speed_sign_train build speed_sign_detector/recognition/data/default_bank.npz \
		$(DATA)/gtsrb-dev $(DATA)/gtsrb-lookalikes-dev --scenes $(DATA)/gtsdb-dev

## validate: the recognition figures too slow for make bench, as JSON in out/validation/ with
## their command and host: 5 folds by track (and by scene, with the scene folds' approach
## sequences and boxes), leave one value out, the rendered sign designs; make bench adds them
## to bench/RESULTS.md. Each is its own target; `make -j2 validate` runs them side by side
## in 40 min to 1.5 h on 2 cores, as fast as the host is that day (folds 36-88 min beside
## leave-one-value-out's 29-75 min, 21 min alone; designs, 30 signs of each value and
## design, about 3 min alone). The banks are trained on one BLAS thread, as make bank and
## bench/redecide_rules.py train them, so that the core count changes no answer
.PHONY: validate validate-folds validate-value-holdout validate-designs
validate: validate-folds validate-value-holdout validate-designs
validate-folds: $(INSTALLED)
	mkdir -p $(OUT)/validation
	$(ONE_BLAS_THREAD) $(BIN)/python bench/record_json.py $(OUT)/validation/folds.json -- \
		$(BIN)/speed_sign_train validate $(DATA)/gtsrb-dev $(DATA)/gtsrb-lookalikes-dev \
		--scenes $(DATA)/gtsdb-dev --approach --boxes --json
validate-value-holdout: $(INSTALLED)
	mkdir -p $(OUT)/validation
	$(ONE_BLAS_THREAD) $(BIN)/python bench/record_json.py $(OUT)/validation/value_holdout.json -- \
		$(BIN)/speed_sign_train validate $(DATA)/gtsrb-dev $(DATA)/gtsrb-lookalikes-dev \
		--leave-one-value-out --json
validate-designs: $(INSTALLED)
	mkdir -p $(OUT)/validation
	$(BIN)/python bench/record_json.py $(OUT)/validation/designs.json -- \
		$(BIN)/python bench/bench_sign_designs.py --per-value 30 --seed 1 --json

## bench: accuracy and speed against the peers: results.json, table and plots in out/bench/,
## and bench/RESULTS.md generated from them (with the JSON of make validate and make soak
## where out/ holds it)
long_run = $(if $(wildcard $(OUT)/$(2)),--$(1) $(OUT)/$(2))
bench: $(INSTALLED)
	$(BIN)/python bench/run_all.py --out $(OUT)/bench --results-md bench/RESULTS.md \
		$(call long_run,validation,validation/folds.json) \
		$(call long_run,value-holdout,validation/value_holdout.json) \
		$(call long_run,designs,validation/designs.json) $(call long_run,soak,soak/soak.json)

## soak: the node fed at 30 Hz by a looping 1280x720 drive for SOAK_MINUTES (an hour): its
## memory every 10 s, every frame answered or counted as dropped, errors, the stamps jumping
## back at each loop without a restart; out/soak/soak.json, rss.csv and the node's log
SOAK_MINUTES ?= 60
.PHONY: soak
soak: $(INSTALLED)
	rm -rf $(OUT)/soak && mkdir -p $(OUT)/soak
	$(BIN)/python bench/bench_soak.py --minutes $(SOAK_MINUTES) --width 1280 --height 720 \
		--rss-csv $(OUT)/soak/rss.csv --node-log $(OUT)/soak/node.log \
		--json > $(OUT)/soak/soak.json

clean:
	rm -rf $(VENV) build install log $(OUT) *.egg-info
