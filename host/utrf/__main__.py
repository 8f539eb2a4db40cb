from utrf.cli import main

raise SystemExit(main())
