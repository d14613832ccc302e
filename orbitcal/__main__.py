from orbitcal.cli import main

raise SystemExit(main())
