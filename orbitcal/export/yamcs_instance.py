"""``yamcs-instance``: a folder a Yamcs 5.12 server runs as it is (CONTRACT section 7).

Files:

* ``etc/yamcs.yaml`` — the server: an ``HttpServer`` on ``127.0.0.1:8090`` (Java properties
  ``-Dorbitcal.yamcs.address=`` / ``-Dorbitcal.yamcs.port=`` change them), one instance,
  ``dataDir: yamcs-data`` (relative to the folder Yamcs starts in);
* ``etc/yamcs.<instance>.yaml`` — the instance: an ``EventRecorder`` (events readable over
  REST and in the web interface), a realtime processor, the MDB (the ``xtce``
  export, ``mdb/<SYSTEM>.xml``) and the streams, ``events_realtime`` among them (a JavaScript
  algorithm raises its events there);
* ``etc/processor.yaml`` — the processor types: ``realtime``, parameters of ``pp_realtime``
  (``--yamcs-inputs telemetered``), and ``realtime-packets``, the same and the packets of
  ``tm_realtime`` (the mission route, docs/yamcs.md);
  ``AlgorithmManager`` and ``LocalParameterManager`` (the local parameters set over REST),
  ``persistParameters`` from ``-Dorbitcal.yamcs.persist=`` (default false: the version rule
  gives the same answer either way, docs/yamcs.md);
* ``mdb/<SYSTEM>.xml`` — the ``xtce`` export with ``yamcs_inputs`` (default ``local``: the raw
  and housekeeping inputs are local parameters, so replayed rows can be set through
  ``POST /api/processors/<instance>/realtime/parameters:batchSet``);
* ``README.md`` — the start command and one replayed row, for the operator who opens the folder.

Keys from Yamcs 5.12.8: ``YamcsServer`` (``--etc-dir``), ``StreamConfig`` (stream types
``tm``, ``cmdHist``, ``event``, ``param``, ``parameterAlarm``, ``eventAlarm``, ``tc``, ``sqlFile``),
``ProcessorConfig`` (``persistParameters``, ``subscribeAll``, ``generateEvents``).
"""

from __future__ import annotations

from orbitcal.export.options import ExportOptions
from orbitcal.export.product import AffineForm, NetworkForm, ProductInfo
from orbitcal.export.xtce import VERSION_RULE, render_xtce

__all__ = ["START_COMMAND", "render_yamcs_instance"]

#: How the folder is started (from inside it): the Yamcs jars of ``fprime-yamcs-bundle``.
START_COMMAND = (
    "java -cp \"$(python -c 'import fprime_yamcs_bundle as b; print(b.LIB_DIR)')/*\" "
    "org.yamcs.YamcsServer --etc-dir etc"
)


def _server(instance: str) -> str:
    return f"""# orbitcal yamcs-instance: the server (Yamcs 5.12)
services:
  - class: org.yamcs.http.HttpServer
    args:
      address: ${{orbitcal.yamcs.address:127.0.0.1}}
      port: ${{orbitcal.yamcs.port:8090}}
instances:
  - {instance}
dataDir: yamcs-data
"""


def _instance(instance: str, mdb_file: str, info: ProductInfo) -> str:
    what = f"calibration {info.spacecraft} v{info.version}"
    return f"""# orbitcal yamcs-instance: instance {instance}, {what}
services:
  - class: org.yamcs.archive.EventRecorder
  - class: org.yamcs.ProcessorCreatorService
    args:
      name: realtime
      type: realtime
mdb:
  - type: xtce
    spec: {mdb_file}
# events_realtime: the MagCalibration JavaScript algorithm raises its events there
streamConfig:
  tm: ["tm_realtime"]
  event: ["events_realtime"]
  param: ["pp_realtime", "sys_param"]
  parameterAlarm: ["alarms_realtime"]
  eventAlarm: ["event_alarms_realtime"]
"""


_PROCESSOR = """# orbitcal yamcs-instance: the processor types. realtime: parameters set over REST
# and from pp_realtime; realtime-packets: the same and the packets of tm_realtime (the mission
# route of orbitcal's docs/yamcs.md: its instance file names a root container for that stream).
realtime:
  services:
    - class: org.yamcs.tctm.StreamParameterProvider
      args:
        stream: "pp_realtime"
    - class: org.yamcs.algorithms.AlgorithmManager
    - class: org.yamcs.parameter.LocalParameterManager
  config: &config
    subscribeAll: true
    generateEvents: true
    persistParameters: ${orbitcal.yamcs.persist:false}
realtime-packets:
  services:
    - class: org.yamcs.StreamTmPacketProvider
      args:
        streams: ["tm_realtime"]
    - class: org.yamcs.tctm.StreamParameterProvider
      args:
        stream: "pp_realtime"
    - class: org.yamcs.algorithms.AlgorithmManager
    - class: org.yamcs.parameter.LocalParameterManager
  config: *config
"""


def _readme(instance: str, system: str, options: ExportOptions, info: ProductInfo) -> str:
    raw = ", ".join(
        f'{{"id": {{"name": "/{system}/{n}"}}, "value": {{"type": "DOUBLE", "doubleValue": 0.0}}}}'
        for n in options.raw_names
    )
    what = f"orbitcal calibration of {info.spacecraft}, version {info.version}"
    return f"""# Yamcs instance `{instance}`: {what}

Start it from this folder (Java 17; `pip install fprime-yamcs-bundle==5.12.8.0` gives the jars):

    {START_COMMAND}

Then set a raw row (and the housekeeping inputs, if any) and read the calibrated values:

    curl -X POST http://127.0.0.1:8090/api/processors/{instance}/realtime/parameters:batchSet \\
      -d '{{"request": [{raw}]}}'
    curl http://127.0.0.1:8090/api/processors/{instance}/realtime/parameters/{system}/{options.cal_names[0]}

{VERSION_RULE}

See docs/yamcs.md in orbitcal for the whole recipe.
"""


def render_yamcs_instance(
    form: AffineForm | NetworkForm, info: ProductInfo, options: ExportOptions
) -> dict[str, bytes]:
    """The folder: relative path → bytes."""
    instance, system = options.yamcs_instance, options.space_system
    mdb_file = f"mdb/{system}.xml"
    return {
        "etc/yamcs.yaml": _server(instance).encode(),
        f"etc/yamcs.{instance}.yaml": _instance(instance, mdb_file, info).encode(),
        "etc/processor.yaml": _PROCESSOR.encode(),
        mdb_file: render_xtce(form, info, options),
        "README.md": _readme(instance, system, options, info).encode(),
    }
