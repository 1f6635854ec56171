from occtool.cli.main import main

main()
