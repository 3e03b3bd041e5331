from wxsky.cli import main

raise SystemExit(main())
