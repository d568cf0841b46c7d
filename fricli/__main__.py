from fricli.cli import main

main()
