#!/usr/bin/env sh
# The report tests open the report in headless Chromium. Install Debian's chromium and
# chromium-driver where they are missing and we may (root, apt); otherwise say so — those
# checks then skip with a note, nothing fails.
if command -v chromium >/dev/null 2>&1 && command -v chromedriver >/dev/null 2>&1; then
    exit 0
fi
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing chromium and chromium-driver for the report's browser tests"
    (apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium chromium-driver) >/dev/null 2>&1 \
        || echo "could not install chromium; the browser checks will skip"
else
    echo "no chromium here and no root to install it; the browser checks will skip"
fi
exit 0
